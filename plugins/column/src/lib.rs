//! The column-type (vertical) machining centre of Pahk, Kim & Moon (1997), section 3: the table
//! moves X on a saddle that moves Y on the bed; the spindle head moves Z on the column.
//!
//! ```text
//! tool branch:      base ─ column ─ Z head ─ spindle (gauge point) ─ tool ball
//! workpiece branch: base ─ Y saddle ─ X table ─ table ball
//! ```
//! Error set (the paper's): positional (degree 1) and straightness (degree 2, pitch and yaw tied)
//! of each axis, squareness XY, YZ, ZX, backlash and servo lag of each axis.
//!
//! Built as a run-time plugin (`libballbar_machine_column.so`): the `ballbar` binary has no
//! machine compiled in and loads this one through the C ABI of `ballbar-plugin-api`. The
//! description itself is [`ballbar_model::machines::column`], which code that links machines
//! statically calls by name.

pub use ballbar_model::machines::{
    COLUMN as NAME, COLUMN_NORM_LENGTH_MM as NORM_LENGTH_MM, column as machine,
};

/// The plugin's description: this machine, as RON. It builds one machine and takes no file.
fn describe(input: &str) -> Result<String, String> {
    if !input.is_empty() {
        return Err(format!("plugin '{NAME}' builds one machine and reads no machine file"));
    }
    ron::ser::to_string(&machine()).map_err(|e| e.to_string())
}

ballbar_plugin_api::declare_plugin! {
    name: NAME,
    version: env!("CARGO_PKG_VERSION"),
    flags: 0,
    describe: describe,
    kernels: [],
}
