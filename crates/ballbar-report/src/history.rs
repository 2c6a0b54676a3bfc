//! A machine parameter over a machine's sessions: the one rule that flags a change between
//! consecutive sessions, used by `ballbar history` (its `*` and the CSV's `significant`) and by
//! the report's trend plots (the changes marked on them), so that both flag the same changes.
//!
//! # The rule
//! Between consecutive sessions `a` and `b` (in date order) where both determined the parameter,
//! the change `d = x_b - x_a` is flagged when `|d| > k u_c` with the combined standard
//! uncertainty `u_c = √(u_a² + u_b²)` (the two fits are independent) and `k` = [`HISTORY_K`].
//! A session that did not determine the parameter (or whose fit has no such parameter) breaks
//! the chain: no change is stated into it or out of it.

/// A change between consecutive sessions is flagged when it exceeds this many combined
/// standard uncertainties (k = 2, about 95 % for normal errors).
pub const HISTORY_K: f64 = 2.0;

/// One session's estimate of a parameter, display units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Value.
    pub value: f64,
    /// Standard uncertainty (k = 1).
    pub u: f64,
    /// Whether the session's fit determined it.
    pub estimable: bool,
}

/// The change into a session from the one before it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Change {
    /// Value now minus value before, display units.
    pub change: f64,
    /// Combined standard uncertainty of the change, `√(u_a² + u_b²)`.
    pub combined_u: f64,
    /// Beyond [`HISTORY_K`] combined standard uncertainties.
    pub flagged: bool,
}

/// The change into each session of `series` (sessions in date order; `None`: the session's fit
/// has no such parameter): `None` for the first session and wherever either side did not
/// determine the parameter.
pub fn changes(series: &[Option<Estimate>]) -> Vec<Option<Change>> {
    let mut out = Vec::with_capacity(series.len());
    let mut prev: Option<Estimate> = None;
    for now in series {
        out.push(match (prev, now) {
            (Some(a), Some(b)) if a.estimable && b.estimable => {
                let change = b.value - a.value;
                let combined_u = a.u.hypot(b.u);
                Some(Change { change, combined_u, flagged: change.abs() > HISTORY_K * combined_u })
            }
            _ => None,
        });
        prev = *now;
    }
    out
}
