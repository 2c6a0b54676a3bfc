//! Example ballbar machine plugin (walked through in `docs/plugins.md`): a bed-type mill whose
//! spindle head grows along Z as the spindle warms up, following the maker's warm-up curve, an
//! error term that needs its own code.
//!
//! ```text
//! tool branch:      base ─ Y cross-slide ─ Z head ─ spindle (gauge point) ─ tool ball
//! workpiece branch: base ─ X table (on the bed) ─ table ball
//! ```
//!
//! The error set is the paper's (positional, straightness with tied angles, squareness,
//! backlash, servo lag) plus the maker's thermal model of the head, one native kernel:
//!
//! $$ \delta_Z(t) = G\,w(t),\quad \varepsilon_X(t) = \frac{G\,w(t)}{h},\qquad
//!    w(t) = 1 - e^{-t/\tau},\ \tau = 15\ \text{min},\ h = 400\ \text{mm}, $$
//!
//! with `t` the time since the session started (the spindle started with the first run) and one
//! unknown coefficient, the head's settled growth `G` (`THZ`, in µm in reports and truth
//! files). The time constant and the tilt lever come from the maker's measurements; the growth
//! itself differs from machine to machine and from day to day, so the fit estimates it.
//!
//! The plugin exports what `ballbar-plugin-api` asks for and nothing else: a description (the
//! machine as RON text) and one kernel, through `declare_plugin!`.

use ballbar_plugin_api::RawJointState;

/// The machine type's name: `ballbar fit --machine bed-mill ...`.
pub const NAME: &str = "bed-mill";

/// The maker's warm-up time constant of the spindle head, s.
pub const WARMUP_TAU_S: f64 = 900.0;

/// The maker's tilt lever: the head pitches about X by its growth over this length, mm.
pub const TILT_LEVER_MM: f64 = 400.0;

/// The machine description: a `ballbar_model::machine::MachineSpec` in RON. Lengths in mm;
/// each linear axis's polynomial terms use `s = (q - reference_mm)/length_mm`. The kernel term
/// names the kernel declared below and the axis whose joint carries it; `unit: Length` means its
/// coefficient is mm inside and µm in reports and truth files.
const MACHINE_RON: &str = r#"(
    name: "bed-mill",
    version: "@VERSION@",
    description: "bed-type mill (table X on the bed, cross-slide Y, head Z) with the maker's warm-up model of the head",
    tool: [
        (name: "Y cross-slide", axis: Y, kind: Linear, direction: (0.0, 1.0, 0.0), origin_mm: (0.0, 0.0, 0.0)),
        (name: "Z head", axis: Z, kind: Linear, direction: (0.0, 0.0, 1.0), origin_mm: (0.0, 0.0, 0.0)),
    ],
    workpiece: [
        (name: "X table", axis: X, kind: Linear, direction: (1.0, 0.0, 0.0), origin_mm: (0.0, 0.0, 0.0)),
    ],
    normalisation: [
        (axis: X, reference_mm: 0.0, length_mm: 400.0),
        (axis: Y, reference_mm: 0.0, length_mm: 250.0),
        (axis: Z, reference_mm: 0.0, length_mm: 250.0),
    ],
    terms: [
        Positional(axis: X, degrees: [1]),
        Positional(axis: Y, degrees: [1]),
        Positional(axis: Z, degrees: [1]),
        Straightness(axis: X, toward: Y, degrees: [2], tie_angles: true),
        Straightness(axis: X, toward: Z, degrees: [2], tie_angles: true),
        Straightness(axis: Y, toward: X, degrees: [2], tie_angles: true),
        Straightness(axis: Y, toward: Z, degrees: [2], tie_angles: true),
        Straightness(axis: Z, toward: X, degrees: [2], tie_angles: true),
        Straightness(axis: Z, toward: Y, degrees: [2], tie_angles: true),
        Squareness(id: "SQXY", axis: X, toward: Y),
        Squareness(id: "SQYZ", axis: Z, toward: Y),
        Squareness(id: "SQZX", axis: Z, toward: X),
        Backlash(axis: X),
        Backlash(axis: Y),
        Backlash(axis: Z),
        ServoLag(axis: X),
        ServoLag(axis: Y),
        ServoLag(axis: Z),
        Kernel(id: "THZ", label: "thermal growth of the Z head, settled value (maker's warm-up curve)", axis: Z,
               kernel: "head_warmup", unit: Length, class: Other),
    ],
)"#;

/// `describe`: this plugin builds one machine and reads no machine file, so its input must be
/// empty. An `Err` reaches the user as `<plugin file>: plugin 'bed-mill' failed in describe: ...`.
fn describe(input: &str) -> Result<String, String> {
    if !input.is_empty() {
        return Err(format!("plugin '{NAME}' builds one machine and reads no machine file"));
    }
    Ok(MACHINE_RON.replace("@VERSION@", env!("CARGO_PKG_VERSION")))
}

/// `w(t)` at session time `t` (s): the fraction of the settled growth reached.
fn warmup(t_s: f64) -> f64 {
    1.0 - (-t_s / WARMUP_TAU_S).exp()
}

/// Kernel `head_warmup`: per unit coefficient (1 mm of settled growth), the error motion of the
/// Z joint at each state: `δz = w(t)` (mm per mm) and the tilt `εx = w(t)/h` (rad per mm). The
/// host calls it once per batch of (up to a few hundred) samples, possibly from several threads
/// at once; `out` is as long as `states`. A time the model cannot take is an `Err`, which the
/// user sees with this plugin's file name.
fn head_warmup(states: &[RawJointState], out: &mut [[f64; 6]]) -> Result<(), String> {
    for (e, s) in out.iter_mut().zip(states) {
        if !(s.session_t_s >= 0.0 && s.session_t_s.is_finite()) {
            return Err(format!(
                "session time {} s: the warm-up model starts at 0 s",
                s.session_t_s
            ));
        }
        let w = warmup(s.session_t_s);
        *e = [0.0, 0.0, w, w / TILT_LEVER_MM, 0.0, 0.0];
    }
    Ok(())
}

ballbar_plugin_api::declare_plugin! {
    name: NAME,
    version: env!("CARGO_PKG_VERSION"),
    flags: 0,
    describe: describe,
    kernels: [("head_warmup", head_warmup)],
}
