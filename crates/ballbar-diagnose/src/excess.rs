//! The gap an engineer means: the excess of a residual RMS above the noise floor, and the share
//! of it an effect closes. Every share of "the gap" the diagnosis states (an accepted effect's,
//! the effects' together, a near miss's "real but minor", the nearest candidates to an
//! unexplained gap, what is left unexplained) is this one, defined here.
//!
//! # The excess
//! A residual of RMS $r$ is the noise (RMS $f$, the floor) plus structure the model lacks. The
//! two are uncorrelated (the noise does not know the machine's errors), so their mean squares
//! add: $r^2 = f^2 + e^2$, and the structure's own RMS, the **excess above the noise**, is
//! $$e(r, f) = \sqrt{\max(r^2 - f^2, 0)}.$$
//! A residual below the floor (a held-out estimate with chance on its side) has no excess.
//!
//! # The share closed
//! An effect that takes the held-out RMS from $r_0$ to $r_1$ closes
//! $$1 - e(r_1, f) / e(r_0, f)$$
//! of the excess: a share of the structure's RMS, in µm, the unit of the numbers printed beside
//! it (held-out RMS 0.294 → 0.255 µm against a floor of 0.250 µm: excess 0.154 → 0.050 µm,
//! 67 % closed). The squared scale (a share of the excess energy, 89 % there) adds up over
//! independent effects but overstates to an engineer what is left in µm on the machine; the
//! linear scale says how much smaller the unexplained error is, so it is the one stated.
//! Shares of energy remain where energy is what is distributed: where the excess lies
//! ([`crate::localise::Where::share`]) and the selection's internal gains, which are converted
//! here ([`closed_from_energy_share`]) before they are said. The raw shrink of the RMS,
//! $1 - r_1/r_0$ (13 % in the example), is kept in the documents as `shrink`, never called the
//! gap. The one wording of the share, on the terminal and the page, is
//! `ballbar_report::vendor::excess_closed_text`.

/// The excess of an RMS `rms` over the noise floor `floor` (any one unit, the same for both):
/// `sqrt(max(rms² − floor², 0))`. NaN when either is NaN.
pub fn excess(rms: f64, floor: f64) -> f64 {
    if rms.is_nan() || floor.is_nan() {
        return f64::NAN;
    }
    (rms * rms - floor * floor).max(0.0).sqrt()
}

/// The share of the excess above the noise closed when the RMS goes from `before` to `after`:
/// `1 − excess(after)/excess(before)`. 1 when `after` is at or below the floor; NaN when there
/// was no excess to close (or a figure is NaN).
pub fn closed(before: f64, after: f64, floor: f64) -> f64 {
    let (e0, e1) = (excess(before, floor), excess(after, floor));
    if e0.is_nan() || e1.is_nan() || e0 <= 0.0 {
        return f64::NAN;
    }
    1.0 - e1 / e0
}

/// The share of the excess closed, from the share of the excess *energy* a gain removes
/// (`gain / (SSE − n·floor²)` on the same samples): `1 − sqrt(max(1 − energy_share, 0))`,
/// the same figure as [`closed`] of the two RMS values.
pub fn closed_from_energy_share(energy_share: f64) -> f64 {
    if energy_share.is_nan() {
        return f64::NAN;
    }
    1.0 - (1.0 - energy_share).max(0.0).sqrt()
}

/// The share of the excess left, from the share of the excess energy left: its square root.
pub fn left_from_energy_share(energy_left: f64) -> f64 {
    energy_left.max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The example, by hand: 0.294² − 0.250² = 0.086436 − 0.0625 = 0.023936, √ =
    /// 0.15471; 0.255² − 0.250² = 0.065025 − 0.0625 = 0.002525, √ = 0.05025; closed
    /// 1 − 0.05025/0.15471 = 0.6752; on the energy scale 1 − 0.002525/0.023936 = 0.8945.
    /// Tolerances: the hand arithmetic's last digit.
    #[test]
    fn the_reversal_spike_example_closes_two_thirds_of_the_excess() {
        assert!((excess(0.294, 0.250) - 0.15471).abs() < 1e-5);
        assert!((excess(0.255, 0.250) - 0.05025).abs() < 1e-5);
        let c = closed(0.294, 0.255, 0.250);
        assert!((c - 0.6752).abs() < 1e-4, "{c}");
        // The energy share of the same step converts to the same figure.
        let energy: f64 = 1.0 - 0.002525 / 0.023936;
        assert!((energy - 0.8945).abs() < 1e-4);
        assert!((closed_from_energy_share(energy) - c).abs() < 1e-9);
        assert!((left_from_energy_share(1.0 - energy) - (1.0 - c)).abs() < 1e-9);
        // Not the raw shrink of the RMS, 1 − 0.255/0.294 = 0.1327.
        assert!((1.0_f64 - 0.255 / 0.294 - 0.1327).abs() < 1e-4);
    }

    #[test]
    fn below_the_floor_there_is_no_excess_and_reaching_it_closes_all() {
        assert_eq!(excess(0.2, 0.25), 0.0);
        assert_eq!(closed(0.3, 0.24, 0.25), 1.0);
        assert!(closed(0.2, 0.1, 0.25).is_nan(), "nothing to close");
        assert!(excess(f64::NAN, 0.25).is_nan());
        assert_eq!(closed_from_energy_share(1.3), 1.0);
    }
}
