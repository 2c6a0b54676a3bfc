//! One wording for each fact that several outputs state (`fit`, `history`, `replay`, the
//! report's page): what a fit did with a parameter it does not estimate, and with the bar
//! length. Every output takes its words from here, so that one fact reads the same wherever
//! it is read.

use ballbar_fit::Fit;
use ballbar_model::ParamClass;
use ballbar_model::machine::BarLength;

/// A parameter these tests cannot determine on its own: no value is reported for it (an
/// individual servo lag, whose mean no radius shows; a term of an axis at rest).
pub const NOT_IDENTIFIABLE: &str = "not identifiable";

/// A parameter these tests cannot determine, which the fit fixes at 0 rather than leave
/// undetermined (a gauge: the bar against the common scale at one radius, ...).
pub const FIXED_AT_0: &str = "fixed at 0";

/// What a fit says of machine parameter `i`, which it does not estimate: [`FIXED_AT_0`] where
/// a gauge fixes it on its own, [`NOT_IDENTIFIABLE`] otherwise.
pub fn not_estimated(f: &Fit, i: usize) -> &'static str {
    if crate::fit_report::fixed_by(f, i).is_some() { FIXED_AT_0 } else { NOT_IDENTIFIABLE }
}

/// What the fit did with the bar length, with the model's option `bar`: "calibrated: its
/// error given as 1.000 µm", "fitted: 0.512 ± 0.020 µm", or, where the runs cannot
/// determine it (one radius: a bar longer by b reads as the axes' common scale), "fixed at 0
/// µm (nominal): these runs cannot tell it from the axes' common scale".
pub fn bar_length(bar: BarLength, f: &Fit) -> String {
    let i = f.parameters.iter().position(|p| p.class == ParamClass::BarLength);
    match (bar, i) {
        (BarLength::Known(b), _) => {
            format!("calibrated: its error given as {:.3} µm (--bar-length-um)", b * 1e3)
        }
        (BarLength::Fit, Some(i)) if f.estimable[i] => {
            format!("fitted: {:.3} ± {:.3} µm", f.values[i] * 1e3, f.std_uncertainty[i] * 1e3)
        }
        (BarLength::Fit, Some(i)) if not_estimated(f, i) == FIXED_AT_0 => format!(
            "{FIXED_AT_0} µm (nominal): these runs cannot tell it from the axes' common scale (a second radius or a calibrated bar can)"
        ),
        (BarLength::Fit, _) => format!("{NOT_IDENTIFIABLE} from these runs"),
    }
}

/// [`not_estimated`] for a parameter of an archived fit, which records whether a gauge fixes
/// it on its own (`fixed`).
pub fn not_estimated_archived(fixed: bool) -> &'static str {
    if fixed { FIXED_AT_0 } else { NOT_IDENTIFIABLE }
}
