//! The horizontal machining centre of Pahk, Kim & Moon (1997): the column moves X on the bed,
//! the spindle head moves Y (vertical) on the column, the spindle points along Z, and the table
//! moves Z towards it.
//!
//! ```text
//! tool branch:      base ─ X column ─ Y head ─ spindle (gauge point) ─ tool ball
//! workpiece branch: base ─ Z table ─ table ball
//! ```
//! The error set is the paper's, as for the column machine. The Y head rides on the X column,
//! so the column's pitch and yaw act with the head height as Abbe arm: the same 18-function
//! span as eq. (40), with other factors in front.
//!
//! Built as a run-time plugin (`libballbar_machine_horizontal.so`). The description itself is
//! [`ballbar_model::machines::horizontal`], which code that links machines statically calls by
//! name.

pub use ballbar_model::machines::{
    HORIZONTAL as NAME, HORIZONTAL_NORM_LENGTH_MM as NORM_LENGTH_MM, horizontal as machine,
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
