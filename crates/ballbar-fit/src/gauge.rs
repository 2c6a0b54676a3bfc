//! What the runs cannot determine, and the choice the fit makes for it: its *gauges*.
//!
//! A ballbar test leaves some parameters, or combinations of them, undetermined. The minimum-norm
//! truncated solution gives them *some* value, and that was harmless only while they were exact
//! null directions of the first-order design. These kinds are known from the tests' geometry and
//! are fixed before the refinement, each stated in the fit ([`Gauge`]):
//!
//! - **An axis that does not move** in any run ([`GaugeKind::AxisAtRest`]): every one of its
//!   terms is fixed at 0. An axis standing still has the error motions of one position in every
//!   run, a constant, which in a test plane moves the circle's centre (the centring takes it)
//!   and out of it changes no reading to first order; how its errors change along its travel the
//!   runs never see. (A file whose coordinates jitter by their last digit would otherwise give
//!   such terms rounding-level columns that look estimable once scaled to unit norm.)
//! - **Parameters that act on no reading** ([`GaugeKind::NoEffect`]: an error normal to every
//!   test plane, a plane term of a plane not tested): fixed at 0. The exact chain still sees
//!   them at second order, so their value must not be left to chance.
//! - **The common servo lag** of the moving axes ([`GaugeKind::CommonLag`]): a lag common to the
//!   axes shifts the ball along its path, which changes no radius to first order; its
//!   second-order radius loss `-V²τ²/(2R)` is a constant at one feed, indistinguishable from the
//!   bar length or the common scale, and the chain models a lag as that shift along the path,
//!   whose second-order effect has the opposite sign of the physical loss (the lagging axes
//!   follow a smaller circle). So the base model cannot identify it at any number of feeds: the
//!   mean lag of the moving axes is taken as 0, which also keeps that unphysical second-order
//!   term out of the refinement. The lag *differences* (the servo mismatch) stay identified;
//!   at several feeds the radius loss is the diagnosis's `servo_lag` effect.
//! - **The bar length against the common scale** ([`GaugeKind::BarLength`]): at one radius a
//!   bar longer by `b` and a common scale `κ` of the axes both change every reading by a
//!   constant (`b` against `κR`). The bar is taken at its nominal length (`BAR = 0`), as a
//!   calibrated bar would give it and as the vendors' software reports the scale errors; the
//!   positional errors then carry the common scale, and the fit says which of its values hold
//!   only for that choice ([`Gauge::conditional`], [`crate::Fit::depends_on`]). The combination
//!   itself is still listed among what the tests cannot separate.
//!
//! - **A run's set-up** ([`GaugeKind::AcrossBar`], [`GaugeKind::SetUp`]): in a rotary run the
//!   bar stays fixed in the table frame, so of the table ball's offset (the run's centring) it
//!   sees only the part along the bar; the two directions across it are fixed at 0
//!   ([`ACROSS_BAR`]). A machine parameter that every run sees only as a re-seated ball (a
//!   rotary table's zero error: the table turned by a constant angle puts the ball at another
//!   place on the table) is fixed at 0 ([`SET_UP_SPAN`]).
//! - **A rotary zero error seen only with other location errors** ([`GaugeKind::ZeroError`]:
//!   the A zero error of a trunnion tilts the C table on it as C's own tilt does, about a pivot
//!   that an offset of C moves): fixed at 0, the others carry it, the combination is reported.
//!   Of such a combination the zero error is the one a ballbar sees least (on a table axis,
//!   never by itself; on a head axis, by a second tool length).
//! - **The lag common to the linear axes, weakly determined** ([`GaugeKind::CommonLag`] again):
//!   where the chain gives the rotary axes no lag term, rotary runs see the linear axes' common lag
//!   against them, through the bar's part along the path; when one standard uncertainty of it
//!   shifts the ball beyond the linear regime, its mean is fixed at 0 as on planar runs.
//!
//! And one kind is found numerically, after those ([`GaugeKind::Weak`]): a combination that the
//! truncation at [`crate::RANK_TOLERANCE`] keeps but that the runs do not determine, by either of
//! two criteria (each justified at its constant):
//!
//! - *aliased to within the coordinates' resolution*: its singular value is below
//!   [`ALIAS_RESOLUTION_FACTOR`] × [`POSITION_RESOLUTION_MM`] / R of the largest. This is
//!   what broke the real XY test at R = 50 mm: the bar length against the common scale sat at
//!   2.4e-9 (an exact alias of the nominal circle, broken by the 1e-6 mm rounding of the run
//!   file's coordinates), just above the 1e-9 truncation, and took a value of -344 m.
//! - *uncertain beyond the linear regime*: its standard uncertainty alone makes a single
//!   parameter's share of the readings exceed `√(2Rσ)`, the displacement whose second-order
//!   effect `Δ²/(2R)` equals the noise σ: within its own uncertainty the direction leaves the
//!   regime in which the first-order design describes the chain, so the runs cannot resolve it.
//!
//! Such a direction is left out of the solution (fixed at 0 along it), reported, and added to
//! what the tests cannot separate.

use ballbar_model::{Axis, Design, ParamClass, TermClass};

pub use ballbar_model::path::POSITION_RESOLUTION_MM;

/// An axis whose commanded coordinate spans less than this in every run stands still, mm. Over
/// 1 µm of travel an error term changes by at most 1 µm / its normalisation length of its size
/// (4e-6 at 250 mm: 0.4 nm of a 100 µm error), far below any bar's resolution; the 1e-6 mm
/// rounding of a run file's coordinates stays 1000× below it, so it never counts as motion.
pub const AXIS_AT_REST_MM: f64 = 1e-3;

/// The same for a rotary axis, rad: 1 µrad turns a point 500 mm from the axis by 0.5 µm
/// (run files give degrees to 1e-7, 1.7e-9 rad).
pub const AXIS_AT_REST_RAD: f64 = 1e-6;

/// A direction whose singular value is below this times [`POSITION_RESOLUTION_MM`] / R (relative
/// to the largest) is aliased to within the coordinates' resolution. The design is computed from
/// coordinates rounded to δq = 1e-6 mm (±δq/2, RMS δq/√12): an alias that is exact on the
/// nominal path is broken by that rounding at a relative singular value of order (δq/√12)/R
/// (measured: 2.4e-9 at R = 50 mm, 0.12 δq/R). 10 δq/R (2e-7 at 50 mm) is 80× above that and
/// still 7000× below the weakest direction that any test of the paper's kind determines
/// (1.4e-3, three planes with two 220° arcs).
pub const ALIAS_RESOLUTION_FACTOR: f64 = 10.0;

/// The floor of the noise σ used by the linear-regime criterion, mm: run files give readings
/// to 1e-4 µm, so a smaller residual is not a noise the data can show (noise-free simulations).
pub const READING_RESOLUTION_MM: f64 = 1e-7;

/// A direction (unit vector) is in a subspace when its part outside is below this, and outside
/// when its part inside is above it: the tolerance [`crate::Fit::functional`] uses for
/// estimability.
pub(crate) const SUBSPACE_TOLERANCE: f64 = 1e-6;

/// What a gauge fixes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GaugeKind {
    /// An axis stands still in every run: its terms are fixed at 0.
    AxisAtRest(Axis),
    /// Parameters that change no reading of these runs to first order: fixed at 0.
    NoEffect,
    /// The lag common to the moving axes: their mean lag is taken as 0.
    CommonLag,
    /// The bar length against the common scale: the bar is taken at its nominal length.
    BarLength,
    /// A combination the runs determine too weakly: fixed at 0 along it.
    Weak,
    /// A run's table-ball offset across its bar (a set-up quantity a rotary run cannot see):
    /// fixed at 0 along it.
    AcrossBar,
    /// Machine parameters that act on every run as a re-seated ball (each run's centring
    /// takes them: a rotary axis's zero error): fixed at 0.
    SetUp,
    /// A rotary axis's zero error that these runs cannot tell from other location errors
    /// (the A zero error from the tilt of the C axis on it): fixed at 0, the others carry it.
    ZeroError,
}

impl Gauge {
    /// True when it sets each of its parameters to 0 (an axis at rest, no effect, the bar
    /// length), rather than a combination of them (the mean lag, a weak combination).
    pub fn fixes_each(&self) -> bool {
        matches!(
            self.kind,
            GaugeKind::AxisAtRest(_)
                | GaugeKind::NoEffect
                | GaugeKind::BarLength
                | GaugeKind::SetUp
                | GaugeKind::ZeroError
        )
    }
}

impl GaugeKind {
    /// A short name for machine-readable reports (`axis_at_rest`, ...).
    pub fn name(self) -> &'static str {
        match self {
            GaugeKind::AxisAtRest(_) => "axis_at_rest",
            GaugeKind::NoEffect => "no_effect",
            GaugeKind::CommonLag => "common_lag",
            GaugeKind::BarLength => "bar_length",
            GaugeKind::Weak => "weakly_determined",
            GaugeKind::AcrossBar => "centring_across_bar",
            GaugeKind::SetUp => "taken_by_set_up",
            GaugeKind::ZeroError => "rotary_zero_error",
        }
    }
}

/// A choice the fit made for something these runs cannot determine.
#[derive(Clone, Debug, PartialEq)]
pub struct Gauge {
    /// What it fixes.
    pub kind: GaugeKind,
    /// What the runs cannot determine ("axis Z does not move in these runs").
    pub what: String,
    /// The choice made ("its terms are fixed at 0: ...").
    pub choice: String,
    /// Why that is the right choice (or why the runs cannot determine it).
    pub why: String,
    /// Which test would determine it.
    pub separate_by: String,
    /// The parameters whose values it sets (column indices): an axis's terms, the bar length,
    /// the lags whose mean it fixes, the parameters of a weak combination.
    pub parameters: Vec<usize>,
    /// Machine parameters whose reported values hold only for this choice (the positional errors
    /// under [`GaugeKind::BarLength`]).
    pub conditional: Vec<usize>,
}

/// A gauge with its linear algebra, in the column-scaled coordinates `z = θ / scale` of the fit.
#[derive(Clone, Debug)]
pub(crate) struct Pending {
    pub gauge: Gauge,
    /// Constraints on the solution, `c·z = 0` for each.
    pub conditions: Vec<Vec<f64>>,
    /// Directions whose values it fixes rather than estimates: they count as not estimable.
    pub fixed: Vec<Vec<f64>>,
    /// Directions the runs cannot see, reported among what the tests cannot separate.
    pub unseen: Vec<Vec<f64>>,
    /// The unseen direction whose value the choice sets, when it differs from `fixed` (the bar
    /// length against the common scale): functionals with a part along it hold for this choice.
    pub dependence: Option<Vec<f64>>,
}

/// A gauge that fixes each of its parameters at 0: each unit vector a condition, a fixed
/// direction and an unseen one.
fn fixing_each(n: usize, gauge: Gauge) -> Pending {
    let e: Vec<Vec<f64>> = gauge.parameters.iter().map(|&j| unit(n, j)).collect();
    Pending { gauge, conditions: e.clone(), fixed: e.clone(), unseen: e, dependence: None }
}

fn unit(n: usize, j: usize) -> Vec<f64> {
    let mut e = vec![0.0; n];
    e[j] = 1.0;
    e
}

/// Normalise `v` to unit length (a zero vector stays zero).
pub(crate) fn normalised(mut v: Vec<f64>) -> Vec<f64> {
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > 0.0 {
        v.iter_mut().for_each(|x| *x /= norm);
    }
    v
}

fn ids(design: &Design<'_>, cols: &[usize]) -> String {
    cols.iter().map(|&j| design.parameters[j].id.as_str()).collect::<Vec<_>>().join(", ")
}

fn axis_list(axes: &[Axis]) -> String {
    axes.iter().map(|a| a.name()).collect::<Vec<_>>().join(", ")
}

/// The axes of the chain that stand still in every run.
pub(crate) fn axes_at_rest(design: &Design<'_>) -> Vec<Axis> {
    design
        .model
        .chain
        .axes()
        .into_iter()
        .filter(|&a| {
            let tol = if a.is_rotary() { AXIS_AT_REST_RAD } else { AXIS_AT_REST_MM };
            !design.runs.iter().any(|run| {
                run.axis(a).is_some_and(|c| {
                    let (lo, hi) =
                        c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                            (lo.min(x), hi.max(x))
                        });
                    hi - lo > tol
                })
            })
        })
        .collect()
}

/// The gauges known before any decomposition: the terms of axes at rest, and machine
/// parameters whose column is zero.
pub(crate) fn structural(design: &Design<'_>, zero_col: &[bool]) -> Vec<Pending> {
    let n = design.n_cols();
    let mut out = Vec::new();
    let mut taken = vec![false; n];
    for a in axes_at_rest(design) {
        let params: Vec<usize> = design
            .model
            .terms
            .iter()
            .enumerate()
            .filter(|(_, t)| t.axis == a)
            .map(|(k, _)| k)
            .collect();
        if params.is_empty() {
            continue;
        }
        params.iter().for_each(|&j| taken[j] = true);
        let separate_by = match a {
            Axis::X => "a test in a plane where X moves (XY or ZX)".to_string(),
            Axis::Y => "a test in a plane where Y moves (XY or YZ)".to_string(),
            Axis::Z => "a test in a plane where Z moves (YZ or ZX)".to_string(),
            _ => format!("a test that turns {a}"),
        };
        out.push(fixing_each(
            n,
            Gauge {
                kind: GaugeKind::AxisAtRest(a),
                what: format!("axis {a} does not move in these runs"),
                choice: format!("its terms are not identifiable and fixed at 0: {}", ids(design, &params)),
                why: format!(
                    "{a} has the error motions of one position in every run: a constant, which in a test plane moves the circle's centre \
                     (the centring takes it) and out of it changes no reading to first order; how its errors change along its travel \
                     these runs never see"
                ),
                separate_by,
                parameters: params,
                conditional: Vec::new(),
            },
        ));
    }
    let idle: Vec<usize> = (0..design.n_machine).filter(|&j| zero_col[j] && !taken[j]).collect();
    if !idle.is_empty() {
        out.push(fixing_each(
            n,
            Gauge {
                kind: GaugeKind::NoEffect,
                what: format!("{} change no reading of these runs", ids(design, &idle)),
                choice: "not identifiable and fixed at 0".into(),
                why: "to first order they act on no reading here (an error normal to every test plane, or a term of a plane not tested); \
                      the exact chain would see them at second order only (Δ²/2R), which these runs cannot resolve"
                    .into(),
                separate_by: "a test in a plane that contains the error's direction".into(),
                parameters: idle,
                conditional: Vec::new(),
            },
        ));
    }
    out
}

/// A run's centring direction whose singular value (within the run's centring columns) is
/// below this fraction of the largest is across the bar. The centring is the table ball's
/// offset in the table frame; in a rotary run a direction of it can stay perpendicular to the
/// bar at every sample (across a radial bar the tangential and axial directions, across an
/// axial bar both radial ones), and then it changes no reading to first order: its column is
/// the rounding of the coordinates (1e-6 mm over R ≥ 50 mm tilts the bar by ≤ 2e-8 rad, so the
/// singular value is ≤ 2e-8 of one along the bar). Scaled to unit norm such a direction would
/// look as well determined as any other and take a value (seen: hundreds of mm) that throws
/// the exact chain out of its linear regime. 1e-6 is 50× above that rounding; a real
/// sensitivity that small would need a 1 mm offset to change a reading by 1 nm.
pub const ACROSS_BAR: f64 = 1e-6;

/// A machine column whose part outside the span of each run's centring is below this
/// fraction of it (over all runs) acts only as a re-seated ball: the rounding of the
/// coordinates leaves an exact alias at about 1e-8 (as for [`ACROSS_BAR`]), a parameter any
/// run sees leaves far more (an offset of a rotary axis in a radial run of it: its first
/// harmonic, of the order of the column itself).
pub const SET_UP_SPAN: f64 = 1e-6;

/// The lag common to the axes with a lag term is taken by the runs' set-up when, rotary axes
/// turning, less than this share of its column lies outside each run's centring (RMS). A run of
/// one rotary axis sees it at most as a constant (the along-bar centring takes it): what is
/// left is the one-sided velocity at the runs' ends, 7e-6 on the A/C trunnion's rotary tests;
/// a run turning two axes together puts 0.11 of it outside. 1e-3 lies two orders of magnitude
/// from both.
pub const LAG_SET_UP: f64 = 1e-3;

/// The gauges of the runs' set-up: the centring directions across their bars
/// ([`ACROSS_BAR`]), each fixed at 0, and the machine parameters that every run sees only as
/// a re-seated ball ([`SET_UP_SPAN`]: a rotary axis's zero error, which turns the table by a
/// constant angle and so moves the table ball to another place on the table), fixed at 0.
/// `blocks` holds per run its design block's global columns (machine columns first) and
/// values; `scale` the fit's column scaling; `taken` the parameters other gauges fix.
pub(crate) fn set_up(
    design: &Design<'_>,
    blocks: &[(&[usize], faer::MatRef<'_, f64>)],
    scale: &[f64],
    zero_col: &[bool],
    taken: &[bool],
) -> Vec<Pending> {
    let n = design.n_cols();
    // The scaled directions fixed: a centring column that is itself across the bar (zero, see
    // `Factorisation::new`) as its unit vector; a combination v of the others as `v / scale`,
    // the direction of the scaled coordinates `z = θ / scale` along which θ moves by v (the
    // columns it combines are of comparable size, so it is a near-null direction of the
    // scaled design, which the minimum-norm solution then leaves at 0).
    let mut dirs = Vec::new();
    let mut params = Vec::new();
    let mut runs = Vec::new();
    // Per machine parameter: its column's energy, and its energy outside the set-up's span.
    let nm = design.n_machine;
    let (mut energy, mut outside) = (vec![0.0; nm], vec![0.0; nm]);
    // The lag common to the axes with a lag term, as one column (equal lags), when a rotary
    // axis turns: its energy and its energy outside the set-up's span.
    let lags: Vec<usize> = (0..nm)
        .filter(|&j| {
            design.parameters[j].class == ParamClass::Term(TermClass::ServoLag)
                && !taken[j]
                && !zero_col[j]
        })
        .collect();
    let rotary_turns = axes_at_rest(design).len() < design.model.chain.axes().len()
        && design
            .model
            .chain
            .axes()
            .iter()
            .filter(|a| a.is_rotary())
            .any(|a| !axes_at_rest(design).contains(a));
    let (mut lag_energy, mut lag_outside) = (0.0, 0.0);
    for (r, (cols, a)) in blocks.iter().enumerate() {
        let centring = design.centring_columns(r);
        let zero: Vec<usize> = centring.clone().filter(|&j| zero_col[j]).collect();
        dirs.extend(zero.iter().map(|&j| unit(n, j)));
        let local: Vec<usize> = (0..cols.len())
            .filter(|&k| centring.contains(&cols[k]) && !zero_col[cols[k]])
            .collect();
        let sub = faer::Mat::<f64>::from_fn(a.nrows(), local.len(), |i, k| a[(i, local[k])]);
        let svd = if local.is_empty() { None } else { crate::jacobi_svd(sub.as_ref()) };
        let mut span: Vec<usize> = Vec::new();
        let mut found = !zero.is_empty();
        if let Some((_, s, v)) = &svd {
            let smax = s.iter().copied().fold(0.0, f64::max);
            for (k, &sk) in s.iter().enumerate() {
                if sk > ACROSS_BAR * smax {
                    span.push(k);
                    continue;
                }
                let mut d = vec![0.0; n];
                for (i, &l) in local.iter().enumerate() {
                    d[cols[l]] = v[(i, k)] / scale[cols[l]];
                }
                dirs.push(normalised(d));
                found = true;
            }
        }
        if found {
            params.extend(centring.clone());
            runs.push(design.runs[r].name());
        }
        for j in 0..nm {
            let Some(k) = cols.iter().position(|&c| c == j) else { continue };
            let col: Vec<f64> = (0..a.nrows()).map(|i| a[(i, k)]).collect();
            let e: f64 = col.iter().map(|x| x * x).sum();
            energy[j] += e;
            let mut rest = col;
            if let Some((u, _, _)) = &svd {
                for &q in &span {
                    let p: f64 = (0..a.nrows()).map(|i| u[(i, q)] * rest[i]).sum();
                    rest.iter_mut().enumerate().for_each(|(i, x)| *x -= p * u[(i, q)]);
                }
            }
            outside[j] += rest.iter().map(|x| x * x).sum::<f64>();
        }
        if rotary_turns && lags.len() >= 2 {
            let mut col = vec![0.0; a.nrows()];
            for &j in &lags {
                if let Some(k) = cols.iter().position(|&c| c == j) {
                    col.iter_mut()
                        .enumerate()
                        .for_each(|(i, x)| *x += a[(i, k)] / lags.len() as f64);
                }
            }
            lag_energy += col.iter().map(|x| x * x).sum::<f64>();
            if let Some((u, _, _)) = &svd {
                for &q in &span {
                    let p: f64 = (0..a.nrows()).map(|i| u[(i, q)] * col[i]).sum();
                    col.iter_mut().enumerate().for_each(|(i, x)| *x -= p * u[(i, q)]);
                }
            }
            lag_outside += col.iter().map(|x| x * x).sum::<f64>();
        }
    }
    let mut out = Vec::new();
    if lag_energy > 0.0 && lag_outside.sqrt() <= LAG_SET_UP * lag_energy.sqrt() {
        let n_l = lags.len() as f64;
        let (mut d, mut g) = (vec![0.0; n], vec![0.0; n]);
        for &j in &lags {
            d[j] = 1.0 / scale[j];
            g[j] = scale[j] / n_l;
        }
        let d = normalised(d);
        let axes: Vec<Axis> = lags.iter().map(|&j| design.model.terms[j].axis).collect();
        out.push(Pending {
            gauge: Gauge {
                kind: GaugeKind::CommonLag,
                what: format!("the servo lag common to {}", axis_list(&axes)),
                choice: format!("not identifiable; the mean of {} is taken as 0 (their differences are identified)", ids(design, &lags)),
                why: format!(
                    "in these runs it shows to first order only as each run's set-up ({:.1e} of it outside): a lag common to the axes \
                     shifts the ball along its path, which a circle and a run of one rotary axis with the bar radial, tangential or \
                     axial see as a constant at most, the part along the bar of the table ball's place; its value would come from second \
                     order alone, where the chain's model of a lag (a shift along the path) is not the machine's",
                    (lag_outside / lag_energy).sqrt()
                ),
                separate_by: "a run that turns two rotary axes together (the path's direction then turns against the bar)".into(),
                parameters: lags.clone(),
                conditional: Vec::new(),
            },
            conditions: vec![normalised(g)],
            fixed: vec![d.clone()],
            unseen: vec![d],
            dependence: None,
        });
    }
    if !dirs.is_empty() {
        let dirs = orthonormal(&dirs);
        out.push(Pending {
            gauge: Gauge {
                kind: GaugeKind::AcrossBar,
                what: format!("the table ball's offset across the bar in {} run(s): {}", runs.len(), runs.join(", ")),
                choice: "fixed at 0 along it (a set-up quantity, not a machine error)".into(),
                why: "the bar stays perpendicular to that offset at every sample of the run, so it changes no reading to first order (and by Δ²/2R to second: 5e-8 mm for 3 µm at R = 100 mm)".into(),
                separate_by: "nothing needed: it is the ball's place on the table, which no machine error depends on".into(),
                parameters: params,
                conditional: Vec::new(),
            },
            conditions: dirs.clone(),
            fixed: dirs,
            unseen: Vec::new(),
            dependence: None,
        });
    }
    let seated: Vec<usize> = (0..nm)
        .filter(|&j| {
            !taken[j] && energy[j] > 0.0 && outside[j].sqrt() <= SET_UP_SPAN * energy[j].sqrt()
        })
        .collect();
    if !seated.is_empty() {
        let all_zero = seated.iter().all(|&j| is_zero_error(&design.parameters[j].id));
        out.push(fixing_each(
            n,
            Gauge {
                kind: GaugeKind::SetUp,
                what: format!("{} act on every run only as a re-seated ball", ids(design, &seated)),
                choice: "not identifiable and fixed at 0".into(),
                why: "each moves the table ball by a constant in the table frame in every run (a zero error turns the table by a constant angle, \
                      which puts the ball at another place on the table): each run's set-up (its centring) takes that, and a ballbar measures \
                      distances, not where on the table the ball sits"
                    .into(),
                separate_by: if all_zero {
                    "an angular reference: a laser interferometer with an angular optic, or a reference artefact probed at two angles".into()
                } else {
                    seated_separation(design, &seated)
                },
                parameters: seated,
                conditional: Vec::new(),
            },
        ));
    }
    out
}

/// The test that separates parameters every run sees only as a re-seated ball, named for the
/// axes they belong to, which are the machine's own: a rotary axis's terms need a test that
/// turns that axis; a linear axis's terms (a backlash on an arc its axis never reverses on, an
/// error that is constant over a short arc) need a path over which the axis reverses and
/// covers more of its travel, which a three-axis machine can run.
pub(crate) fn seated_separation(design: &Design<'_>, seated: &[usize]) -> String {
    let mut rotary: Vec<Axis> = Vec::new();
    let mut linear: Vec<Axis> = Vec::new();
    for &j in seated {
        let Some(t) = design.model.terms.get(j) else { continue };
        let list = if t.axis.is_rotary() { &mut rotary } else { &mut linear };
        if !list.contains(&t.axis) {
            list.push(t.axis);
        }
    }
    let mut parts = Vec::new();
    if !rotary.is_empty() {
        parts.push(format!(
            "a rotary test that turns {} (the bar radial at two heights, tangential, axial)",
            axis_list(&rotary)
        ));
    }
    if !linear.is_empty() {
        parts.push(format!(
            "a full circle, or an arc across the reversals of {}: over it the axes move both ways and over more of their travel, where these terms are no longer a constant",
            axis_list(&linear)
        ));
    }
    if parts.is_empty() { "a test over more of the axes' travel".into() } else { parts.join("; ") }
}

/// A machine column below this fraction of the largest machine column of the same unit is
/// checked against the exact chain ([`rounding_only`]): only a column this small can owe its
/// size to the rounding of the coordinates (an error normal to the test plane, seen through a
/// normal coordinate that jitters in its last digit: 1e-6 mm of R, 2e-8 at 50 mm). A column
/// of a high-degree term near its reference can be as small and is genuine: the exact chain
/// tells them apart, and is evaluated only for these few.
pub const SUSPECT_COLUMN_RATIO: f64 = 1e-4;

/// The step of a parameter for the exact-chain check, in its display unit (100 µm, 100 µrad,
/// 100 ms, ...): large enough that the second-order response stands far above the rounding of
/// the distance (1e-14 mm), small enough that the chain stays near its linear regime.
const PROBE_STEP_DISPLAY: f64 = 100.0;

/// The first-order readings per run of parameters `θ` (the design's `A θ`) for parameter `j`.
pub(crate) type FirstOrder<'a> =
    dyn Fn(usize, &[f64]) -> Result<Vec<Vec<f64>>, ballbar_model::ModelError> + 'a;

/// The exact readings per run of parameters `θ`.
pub(crate) type Exact<'a> = dyn Fn(&[f64]) -> Result<Vec<Vec<f64>>, ballbar_model::ModelError> + 'a;

/// Machine parameters (among `candidates`) that act on these runs only through the rounding of
/// their coordinates: the exact chain shows that they displace the ball, but their first-order
/// share of the readings is at most `alias_limit` (10 δq/R, [`ALIAS_RESOLUTION_FACTOR`]) of that
/// displacement. The displacement is measured by the second-order response of the exact chain
/// to a step h: `N ≈ (h|Δ|)²/(2R)`, so `h|Δ| ≈ √(2RN)`. Scaled to unit norm, such a column
/// would look as well determined as any other and take a value that throws the exact chain
/// far out of its linear regime (seen: 4e6 mm). `first` is the first-order share of a step per
/// run (`A h e_j`), `exact(θ)` the exact readings per run.
pub(crate) fn rounding_only(
    design: &Design<'_>,
    candidates: &[usize],
    alias_limit: f64,
    first: &FirstOrder<'_>,
    exact: &Exact<'_>,
) -> Result<Vec<(usize, f64)>, ballbar_model::ModelError> {
    let n = design.n_cols();
    let m = design.n_rows() as f64;
    let rmin = design.runs.iter().map(|r| r.header.radius_mm).fold(f64::INFINITY, f64::min);
    let rms = |v: &[Vec<f64>]| (v.iter().flatten().map(|x| x * x).sum::<f64>() / m).sqrt();
    let base = exact(&vec![0.0; n])?;
    let mut out = Vec::new();
    for &j in candidates {
        let mut theta = vec![0.0; n];
        theta[j] = PROBE_STEP_DISPLAY / design.parameters[j].unit.display_factor();
        let lin = first(j, &theta)?;
        let ex = exact(&theta)?;
        let second: Vec<Vec<f64>> = ex
            .iter()
            .zip(&base)
            .zip(&lin)
            .map(|((e, b), l)| e.iter().zip(b).zip(l).map(|((e, b), l)| e - b - l).collect())
            .collect();
        let displacement = (2.0 * rmin * rms(&second)).sqrt();
        let share = rms(&lin);
        if displacement > 0.0 && share <= alias_limit * displacement {
            out.push((j, share / displacement));
        }
    }
    Ok(out)
}

/// The gauge of parameters that act only through the coordinates' rounding.
pub(crate) fn rounding_gauge(design: &Design<'_>, found: &[(usize, f64)]) -> Pending {
    let n = design.n_cols();
    let params: Vec<usize> = found.iter().map(|p| p.0).collect();
    let worst = found.iter().map(|p| p.1).fold(0.0, f64::max);
    fixing_each(
        n,
        Gauge {
            kind: GaugeKind::NoEffect,
            what: format!(
                "{} act on these runs only through the rounding of their coordinates",
                ids(design, &params)
            ),
            choice: "not identifiable and fixed at 0".into(),
            why: format!(
                "their first-order share of the readings is at most {worst:.1e} of the displacement they make (an error normal to \
                 the test planes, seen through a normal coordinate that differs from the pivot's by rounding): below 10 × 1e-6 mm / R, \
                 it is rounding, and the displacement itself enters only at second order (Δ²/2R)"
            ),
            separate_by: "a test in a plane that contains the error's direction".into(),
            parameters: params,
            conditional: Vec::new(),
        },
    )
}

/// Orthonormalise `vectors`, each of length at most 1 (unit vectors, or their projections),
/// by modified Gram-Schmidt, twice: a vector whose part outside the ones before it is below
/// [`SUBSPACE_TOLERANCE`] is dropped (it is in their span, or it was a rounding-level
/// remainder of a projection).
pub(crate) fn orthonormal<'a>(vectors: impl IntoIterator<Item = &'a Vec<f64>>) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::new();
    for v in vectors {
        let mut w: Vec<f64> = v.clone();
        for _ in 0..2 {
            for q in &out {
                let p: f64 = w.iter().zip(q).map(|(a, b)| a * b).sum();
                w.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
            }
        }
        let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > SUBSPACE_TOLERANCE {
            w.iter_mut().for_each(|x| *x /= norm);
            out.push(w);
        }
    }
    out
}

/// The projection of `v` onto the span of the orthonormal `basis`.
pub(crate) fn project(v: &[f64], basis: &[Vec<f64>]) -> Vec<f64> {
    let mut p = vec![0.0; v.len()];
    for q in basis {
        let c: f64 = v.iter().zip(q).map(|(a, b)| a * b).sum();
        p.iter_mut().zip(q).for_each(|(a, b)| *a += c * b);
    }
    p
}

/// The projection of `v` on the part of the span of `basis` (orthonormal) whose vectors are 0
/// at the coordinates `excluded`: what `v` is confused with once those parameters are fixed
/// by their own gauges (the bar length's combination without the zero errors', and the
/// reverse). Each excluded coordinate is eliminated from the basis by the vector with its
/// largest component (Gaussian elimination with pivoting), the rest orthonormalised. When
/// nothing is left, the plain projection.
fn project_without(v: &[f64], basis: &[Vec<f64>], excluded: &[usize]) -> Vec<f64> {
    let mut b: Vec<Vec<f64>> = basis.to_vec();
    for &k in excluded {
        let Some(piv) = (0..b.len()).max_by(|&x, &y| b[x][k].abs().total_cmp(&b[y][k].abs()))
        else {
            break;
        };
        if b[piv][k].abs() <= SUBSPACE_TOLERANCE {
            continue;
        }
        let p = b.remove(piv);
        for w in &mut b {
            let f = w[k] / p[k];
            w.iter_mut().zip(&p).for_each(|(x, y)| *x -= f * y);
        }
    }
    let reduced = orthonormal(&b);
    let out = project(v, &reduced);
    if norm(&out) > SUBSPACE_TOLERANCE { out } else { project(v, basis) }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The gauges that depend on what the runs cannot see (`unseen`: an orthonormal basis of the
/// null and weakly determined directions, scaled coordinates): the common lag and the bar
/// length. `scale` are the column scales, `taken` the parameters other gauges already fix.
/// The lag common to the linear axes determined too weakly to stay in the linear regime
/// (`Factorisation::lag_weakness`): its standard uncertainty, s, the shift of the ball along
/// its path that makes at the largest feed, mm, and the regime's limit √(2Rσ), mm.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LagWeakness {
    pub u_s: f64,
    pub shift_mm: f64,
    pub limit_mm: f64,
}

pub(crate) fn lag_and_bar(
    design: &Design<'_>,
    scale: &[f64],
    zero_col: &[bool],
    unseen: &[Vec<f64>],
    taken: &[bool],
    lag_weak: Option<LagWeakness>,
) -> Vec<Pending> {
    let n = design.n_cols();
    let mut out = Vec::new();
    // The common lag: one lag term per moving axis, all equal. In scaled coordinates the
    // internal direction d is d / scale; the condition "mean 0" is (g ⊙ scale)·z = 0.
    let lags: Vec<usize> = (0..design.model.terms.len())
        .filter(|&j| {
            design.parameters[j].class == ParamClass::Term(TermClass::ServoLag)
                && !taken[j]
                && !zero_col[j]
        })
        .collect();
    if lags.len() >= 2 {
        let mut d = vec![0.0; n];
        let mut g = vec![0.0; n];
        for &j in &lags {
            d[j] = 1.0 / scale[j];
            g[j] = scale[j] / lags.len() as f64;
        }
        let d = normalised(d);
        let inside = project(&d, unseen);
        let outside: f64 =
            d.iter().zip(&inside).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
        if outside <= SUBSPACE_TOLERANCE || lag_weak.is_some() {
            let axes: Vec<Axis> = lags.iter().map(|&j| design.model.terms[j].axis).collect();
            out.push(Pending {
                gauge: Gauge {
                    kind: GaugeKind::CommonLag,
                    what: format!("the servo lag common to {}", axis_list(&axes)),
                    choice: format!("not identifiable; the mean of {} is taken as 0 (their differences, the servo mismatch, are identified)", ids(design, &lags)),
                    why: match lag_weak {
                        Some(w) if outside > SUBSPACE_TOLERANCE => format!(
                            "a lag common to these axes shows only against the axes without a lag term (rotary axes the chain gives \
                             none), in rotary runs, through the bar's part along the path: these runs determine it to ±{:.1} ms, which shifts the \
                             ball along its path by {:.3} mm at their feed, beyond the {:.3} mm where its second order reaches the noise; \
                             a mean lag of 0 keeps that far-from-linear shift out of the other parameters (a run that turns two rotary \
                             axes together determines it)",
                            w.u_s * 1e3,
                            w.shift_mm,
                            w.limit_mm
                        ),
                        _ => "a lag common to the moving axes shifts the ball along its path, which changes no radius to first order; its \
                              radius loss V²τ²/(2R) is second order, a constant at one feed (taken by the bar length or the scale), and the \
                              chain's model of a lag (a shift along the path) gives it with the wrong sign: a mean lag of 0 keeps that term \
                              out of the refinement"
                            .into(),
                    },
                    separate_by: if lag_weak.is_some() && outside > SUBSPACE_TOLERANCE {
                        "a run that turns two rotary axes together (the path's direction then turns against the bar)".into()
                    } else {
                        "a common lag changes no radius to first order: runs at two feeds show its radius loss (diagnose: servo_lag)".into()
                    },
                    parameters: lags.clone(),
                    conditional: Vec::new(),
                },
                conditions: vec![normalised(g)],
                fixed: vec![d.clone()],
                unseen: vec![d],
                dependence: None,
            });
        }
    }
    // The bar length: if its unit vector has a part in the unseen space, the runs cannot tell
    // it from something else (at one radius, the common scale of the axes). That part, p, is
    // the unseen direction the choice BAR = 0 sets.
    if let Some(bar) = (0..design.n_machine)
        .find(|&j| design.parameters[j].class == ParamClass::BarLength && !taken[j] && !zero_col[j])
    {
        let e = unit(n, bar);
        if norm(&project(&e, unseen)) > SUBSPACE_TOLERANCE {
            // The zero errors have gauges of their own (`zero_errors`): not what the bar trades with.
            let zeros: Vec<usize> = (0..design.n_machine)
                .filter(|&j| is_zero_error(&design.parameters[j].id) && !zero_col[j])
                .collect();
            let p = normalised(project_without(&e, unseen, &zeros));
            // The machine parameters it is confused with (above 1e-3 of the largest, display units).
            let disp: Vec<f64> = (0..n)
                .map(|j| p[j] * scale[j] * design.parameters[j].unit.display_factor())
                .collect();
            // Parameters other gauges fix are left out: their columns may be at rounding level,
            // which the scale turns into large display amounts of rounding noise.
            let free = |j: usize| j != bar && !taken[j] && !zero_col[j];
            let top = (0..design.n_machine)
                .filter(|&j| free(j))
                .map(|j| disp[j].abs())
                .fold(0.0, f64::max);
            let with: Vec<usize> = (0..design.n_machine)
                .filter(|&j| free(j) && top > 0.0 && disp[j].abs() > 1e-3 * top)
                .collect();
            let radii: Vec<f64> = design.runs.iter().map(|r| r.header.radius_mm).collect();
            let one_radius = radii.iter().all(|&r| (r - radii[0]).abs() <= 1e-9 * radii[0].abs());
            let positional = with
                .iter()
                .all(|&j| design.parameters[j].class == ParamClass::Term(TermClass::Positional));
            let what = if one_radius && positional && !with.is_empty() {
                format!(
                    "the bar length against the common scale of the axes ({}) at one radius, R = {} mm",
                    ids(design, &with),
                    radii[0]
                )
            } else if with.is_empty() {
                "the bar length".to_string()
            } else {
                format!("the bar length against {}", ids(design, &with))
            };
            out.push(Pending {
                gauge: Gauge {
                    kind: GaugeKind::BarLength,
                    what,
                    choice: "not identifiable together: the bar is taken at its nominal length (BAR = 0), as a calibrated bar would give \
                             it, so the positional errors carry the common scale"
                        .into(),
                    why: "a bar longer by b and a common scale κ of the axes both change every reading of a circle of radius R by a \
                          constant (b against κR): the runs see only their sum"
                        .into(),
                    separate_by: if one_radius {
                        "a second radius (scale grows with R, bar length does not), or a calibrated bar (--bar-length-um)".into()
                    } else {
                        // Two radii already: what else trades with the scale (a rotary axis's
                        // offsets, which move with the scale of the axes that place its line)
                        // keeps it open.
                        "a calibrated bar (--bar-length-um): these runs' radii do not separate it, as the parameters above move with the common scale too".into()
                    },
                    parameters: vec![bar],
                    conditional: Vec::new(),
                },
                conditions: vec![e.clone()],
                fixed: vec![e],
                unseen: vec![p.clone()],
                dependence: Some(p),
            });
        }
    }
    out.extend(zero_errors(design, scale, zero_col, unseen, taken));
    out
}

/// True when the rotary axis of the location error `id` (`E<d>0<k>`) is on the tool branch.
fn on_tool_branch(design: &Design<'_>, id: &str) -> bool {
    let k = id.get(3..4).and_then(Axis::from_name);
    design.model.chain.tool.iter().any(|j| Some(j.axis) == k)
}

/// True for the id of a rotary axis's zero error (ISO 230-7 `E<k>0<k>`: `EC0C`, `EA0A`).
pub fn is_zero_error(id: &str) -> bool {
    let b = id.as_bytes();
    b.len() == 4
        && b[0] == b'E'
        && b[2] == b'0'
        && b[1] == b[3]
        && matches!(b[1], b'A' | b'B' | b'C')
}

/// The rotary zero errors that the runs cannot tell from other parameters (their unit vectors
/// have a part in the unseen space): each fixed at 0. A ballbar measures distances, so a zero
/// error shows only through what it moves, and another location error can move the same (the
/// A zero error tilts the C table on the trunnion exactly as a tilt of C about X does, about a
/// pivot that an offset of C shifts): of the combination, the zero error is the one a ballbar
/// sees least (on a table axis never by itself, an angular reference gives it; on a head axis
/// a second tool length, as the tool ball swings by the tool length times it). The others' values then hold
/// for that choice ([`Gauge::conditional`]).
fn zero_errors(
    design: &Design<'_>,
    scale: &[f64],
    zero_col: &[bool],
    unseen: &[Vec<f64>],
    taken: &[bool],
) -> Vec<Pending> {
    let n = design.n_cols();
    let mut out = Vec::new();
    for j in (0..design.n_machine)
        .filter(|&j| is_zero_error(&design.parameters[j].id) && !taken[j] && !zero_col[j])
    {
        let e = unit(n, j);
        if norm(&project(&e, unseen)) <= SUBSPACE_TOLERANCE {
            continue;
        }
        // What it trades with once the bar length and the other zero errors are fixed by
        // their own gauges.
        let others: Vec<usize> = (0..design.n_machine)
            .filter(|&k| {
                k != j
                    && !zero_col[k]
                    && (design.parameters[k].class == ParamClass::BarLength
                        || is_zero_error(&design.parameters[k].id))
            })
            .collect();
        let p = project_without(&e, unseen, &others);
        let p = normalised(p);
        let disp: Vec<f64> =
            (0..n).map(|k| p[k] * scale[k] * design.parameters[k].unit.display_factor()).collect();
        let top = (0..design.n_machine)
            .filter(|&k| k != j && !taken[k] && !zero_col[k])
            .map(|k| disp[k].abs())
            .fold(0.0, f64::max);
        let with: Vec<usize> = (0..design.n_machine)
            .filter(|&k| {
                k != j && !taken[k] && !zero_col[k] && top > 0.0 && disp[k].abs() > 1e-3 * top
            })
            .collect();
        let id = &design.parameters[j].id;
        out.push(Pending {
            gauge: Gauge {
                kind: GaugeKind::ZeroError,
                what: if with.is_empty() { format!("the zero error {id}") } else { format!("the zero error {id} against {}", ids(design, &with)) },
                choice: format!("not identifiable together: {id} is taken as 0, and the others carry it"),
                why: format!(
                    "these runs see only a combination of them: {id} turns everything the axis carries by a constant angle, which the \
                     others reproduce (a tilt of the axis it carries, about a pivot that an offset moves)"
                ),
                separate_by: if on_tool_branch(design, id) {
                    format!("a second tool length in the runs that turn it (the tool ball swings by the tool length times {id}, the offsets it trades with do not grow with it), or an angular reference")
                } else {
                    format!("an angular reference for {id}: a laser interferometer with an angular optic, or a reference artefact probed at two angles")
                },
                parameters: vec![j],
                conditional: Vec::new(),
            },
            conditions: vec![e.clone()],
            fixed: vec![e],
            unseen: vec![p.clone()],
            dependence: Some(p),
        });
    }
    out
}

/// Why a kept direction is not determined.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Weakness {
    /// Relative singular value below the coordinates' resolution limit.
    Aliased { relative: f64, limit: f64 },
    /// A single parameter's share of the readings within one standard uncertainty, mm, against
    /// the linear-regime limit √(2Rσ), mm.
    Nonlinear { share_mm: f64, limit_mm: f64 },
}

/// The gauge of a weakly determined direction `v` (scaled coordinates).
/// `taken`: parameters other gauges fix (their parts, rounding noise times their scale, are left
/// out of the description).
pub(crate) fn weak(
    design: &Design<'_>,
    scale: &[f64],
    taken: &[bool],
    v: &[f64],
    why: Weakness,
) -> Pending {
    let n = design.n_cols();
    let disp: Vec<f64> = (0..n)
        .map(|j| {
            if taken[j] {
                0.0
            } else {
                v[j] * scale[j] * design.parameters[j].unit.display_factor()
            }
        })
        .collect();
    let top = disp.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let mut params: Vec<usize> =
        (0..n).filter(|&j| top > 0.0 && disp[j].abs() > 1e-3 * top).collect();
    params.sort_by(|&a, &b| disp[b].abs().total_cmp(&disp[a].abs()));
    let shown: Vec<String> = params
        .iter()
        .take(6)
        .map(|&j| {
            format!(
                "{} {:+.3} {}",
                design.parameters[j].id,
                disp[j] / top,
                design.parameters[j].unit.display_name()
            )
        })
        .collect();
    let more = if params.len() > 6 {
        format!(", … ({} parameters)", params.len())
    } else {
        String::new()
    };
    let why = match why {
        Weakness::Aliased { relative, limit } => format!(
            "aliased to within the run files' coordinate resolution: its singular value is {relative:.1e} of the largest, below \
             {limit:.1e} (10 × 1e-6 mm / R), where the rounding of the coordinates alone puts an exact alias of the nominal path"
        ),
        Weakness::Nonlinear { share_mm, limit_mm } => format!(
            "within one standard uncertainty a single parameter's share of the readings would reach {:.3} mm, beyond the {:.3} mm at \
             which the chain's second-order effect (Δ²/2R) equals the noise: the runs cannot resolve it within the first-order model",
            share_mm, limit_mm
        ),
    };
    Pending {
        gauge: Gauge {
            kind: GaugeKind::Weak,
            what: format!("a weakly determined combination: {}{more}", shown.join(", ")),
            choice: "not identifiable; fixed at 0 along it (left out of the solution)".into(),
            why,
            separate_by: "full circles, more planes, radii or tool lengths, or fewer terms".into(),
            parameters: params,
            conditional: Vec::new(),
        },
        conditions: vec![v.to_vec()],
        fixed: vec![v.to_vec()],
        unseen: vec![v.to_vec()],
        dependence: None,
    }
}
