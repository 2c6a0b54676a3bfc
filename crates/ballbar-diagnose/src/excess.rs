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
//!
//! # Its uncertainty
//! Near the floor the share is the ratio of two small differences of squares, and what is
//! known of them is uncertain ([`share`]). An estimate $D = r^2 - f^2$ of the excess energy on
//! $n$ held-out samples errs by
//! - the floor's own error: $-2 f\,\delta f$, standard uncertainty $2 f\,u(f)$
//!   ([`crate::localise::noise_floor`]);
//! - the held-out noise's own chance: its mean square over the $n$ samples differs from σ² by
//!   a variance $(2/n) \sum_k \gamma(k)^2$ (the noise's autocovariance, all lags:
//!   [`crate::localise::Noise::mean_square_variance`]);
//! - the cross term of the structure $s$ and the noise, $2\,\overline{s\,n}$, of variance at
//!   most $4 e^2 σ^2 κ / n$ (κ the noise's long-run variance over its variance, the worst case
//!   of a structure slow against the noise's correlation).
//!
//! They add in quadrature to $u(D)$. The first two move the figures before and after the
//! effects alike (the same samples, the same floor), the cross term each alone; the share's
//! interval at $k = 1$ moves it by each source in turn (the first two together, $D_0$ and
//! $D_1$ by $\pm u_c$; each cross term on its own figure) and adds the moves in quadrature
//! either way: about two thirds of the time it holds the share the same tests would show
//! without chance. Where $D_0$ is within
//! [`DETERMINED_K`] of its $u$ of zero, the excess itself is not told from the noise and the
//! share is **not determined**: said so, with the RMS before and after and the bound the
//! excess lies below ($\sqrt{\max(D_0, 0) + 2u}$), instead of a number.

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

/// What the chance of held-out figures rests on besides their two RMS values
/// (the module's "Its uncertainty"), in the unit of the RMS.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chance {
    /// The floor's standard uncertainty.
    pub floor_u: f64,
    /// The variance of the held-out noise's mean square about σ² (unit⁴).
    pub mean_square_var: f64,
    /// The variance of the cross term of structure and noise per unit of excess energy
    /// (unit²): `4σ²κ/n`.
    pub cross_var_per_excess: f64,
}

impl Chance {
    /// The chance of figures over `n` held-out samples of the noise `noise` (its floor's u
    /// included).
    pub fn of(noise: &crate::localise::Noise, n: usize) -> Chance {
        let var = noise.sigma * noise.sigma;
        Chance {
            floor_u: noise.sigma_u,
            mean_square_var: noise.mean_square_variance(n),
            cross_var_per_excess: if n > 0 {
                4.0 * var * noise.inflation() / n as f64
            } else {
                f64::NAN
            },
        }
    }

    /// The standard uncertainty (unit²) of the excess energy `rms² − floor²` estimated from
    /// a held-out RMS `rms` against the floor `floor`. A floor without its u counts as exact.
    pub fn excess_energy_u(&self, rms: f64, floor: f64) -> f64 {
        let floor_u = if self.floor_u.is_nan() { 0.0 } else { self.floor_u };
        let d = (rms * rms - floor * floor).max(0.0);
        ((2.0 * floor * floor_u).powi(2) + self.mean_square_var + self.cross_var_per_excess * d)
            .sqrt()
    }
}

/// The excess energy must stand this many of its standard uncertainties above zero for its
/// share to be determined (k = 2, as the project's decisions against a limit take U = 2u).
pub const DETERMINED_K: f64 = 2.0;

/// The share of the excess above the noise closed, as it can be stated ([`share`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Share {
    /// Whether the excess before stands [`DETERMINED_K`] standard uncertainties above zero.
    pub determined: bool,
    /// [`closed`] when determined; NaN otherwise.
    pub closed: f64,
    /// The share at the excess energies ∓ their standard uncertainty (k = 1), low first; NaN
    /// when not determined.
    pub interval: [f64; 2],
    /// The excess before, [`excess`] of the RMS before.
    pub excess_before: f64,
    /// The bound the excess before lies below: `sqrt(max(D₀, 0) + k u(D₀))`, k = 2.
    pub excess_before_bound: f64,
    /// `u(D₀)`, the standard uncertainty of the excess energy before (unit²).
    pub excess_energy_u: f64,
}

/// The share of the excess above the noise closed when the held-out RMS goes from `before` to
/// `after` against `floor`, with its interval, or not determined (the module's "Its
/// uncertainty").
pub fn share(before: f64, after: f64, floor: f64, chance: &Chance) -> Share {
    let u = chance.excess_energy_u(before, floor);
    let (d0, d1) = (before * before - floor * floor, after * after - floor * floor);
    let bound = (d0.max(0.0) + DETERMINED_K * u).sqrt();
    let determined = d0 > DETERMINED_K * u && u.is_finite();
    let of = |a: f64, b: f64| 1.0 - (b.max(0.0) / a).sqrt();
    let (closed, interval) = if determined {
        let s = of(d0, d1);
        // Each source's two ends: the common part (floor and noise) moves both energies
        // alike; each figure's cross term moves it alone.
        let common = chance.excess_energy_u(floor, floor);
        let (c0, c1) = (
            (chance.cross_var_per_excess * d0.max(0.0)).sqrt(),
            (chance.cross_var_per_excess * d1.max(0.0)).sqrt(),
        );
        let ends = [
            (of(d0 + common, d1 + common), of(d0 - common, d1 - common)),
            (of(d0 - c0, d1), of(d0 + c0, d1)),
            (of(d0, d1 + c1), of(d0, d1 - c1)),
        ];
        let (mut down, mut up) = (0.0, 0.0);
        for (p, q) in ends {
            down += (s - p.min(q)).max(0.0).powi(2);
            up += (p.max(q) - s).max(0.0).powi(2);
        }
        (self::closed(before, after, floor), [s - down.sqrt(), (s + up.sqrt()).min(1.0)])
    } else {
        (f64::NAN, [f64::NAN; 2])
    };
    Share {
        determined,
        closed,
        interval,
        excess_before: excess(before, floor),
        excess_before_bound: bound,
        excess_energy_u: u,
    }
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

    /// The interval by hand: floor 0.250 ± 0.002 µm, mean-square variance 4e-6 µm⁴ (its sd
    /// 0.002 µm²), no cross term: u(D) = √((2·0.25·0.002)² + 4e-6) = √(1e-6 + 4e-6) =
    /// 0.0022361 µm². Before 0.294, after 0.255 (D₀ 0.023936, D₁ 0.002525): determined;
    /// the share 1 − √(0.0047611/0.0261721) = 0.57349 low, 1 − √(0.0002889/0.0216999) =
    /// 0.88462 high. Before 0.255 (D₀ 0.002525 < 2u = 0.0044721): not determined, below
    /// √(0.002525 + 0.0044721) = 0.083648 µm.
    #[test]
    fn a_share_carries_its_interval_and_one_near_the_floor_is_not_determined() {
        let c = Chance { floor_u: 0.002, mean_square_var: 4e-6, cross_var_per_excess: 0.0 };
        assert!((c.excess_energy_u(0.294, 0.25) - 0.0022361).abs() < 1e-7);
        let s = share(0.294, 0.255, 0.25, &c);
        assert!(s.determined);
        assert!((s.closed - 0.6752).abs() < 1e-4, "{s:?}");
        assert!((s.interval[0] - 0.57349).abs() < 1e-4, "{s:?}");
        assert!((s.interval[1] - 0.88462).abs() < 1e-4, "{s:?}");
        let s = share(0.255, 0.251, 0.25, &c);
        assert!(!s.determined && s.closed.is_nan() && s.interval[0].is_nan(), "{s:?}");
        assert!((s.excess_before_bound - 0.083648).abs() < 1e-5, "{s:?}");
        assert!((s.excess_before - 0.05025).abs() < 1e-5, "{s:?}");
        // An effect that makes the figure worse: its interval is still low first.
        let s = share(0.294, 0.296, 0.25, &c);
        assert!(s.determined && s.interval[0] <= s.closed && s.closed <= s.interval[1], "{s:?}");
    }
}
