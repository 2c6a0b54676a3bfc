//! Step 2 of the method: the candidate library.
//!
//! The candidate library ([`library`]): every effect of [`Effect`] that the base model
//! lacks, on every axis the chain has, with its non-linear parameters on a grid (a reversal
//! spike's decay time and ringing frequency, [`Effect::ReversalTransient`]; stick-slip
//! speed; a thermal growth's time constant, or none, when the session spans ten minutes or
//! more; with runs at two feeds or more, a spike's and a stick-slip's size scaled by the
//! feed to an exponent, [`Effect::FeedScaled`]), at the peaks of a periodogram against axis position (cyclic pitch) or
//! of the power spectrum against time summed over runs (vibration frequency; a vibration has
//! one pair of columns per run, its phase being each run's own). With two runs or more, each
//! run's own bar length ([`Effect::BarLengthDrift`], one column per run; the selection says
//! how it is judged).

use std::ops::Range;

use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Axis, Design, Effect, KernelSource, ModelError, Plane, Run};

use crate::localise;

/// A rotary axis turns in a run when its coordinate spans more than this, rad (10°: a sweep
/// short of that holds a harmonic of the angle as a polynomial of low degree, which the
/// location errors already are).
pub(crate) const ROTARY_TURNS_RAD: f64 = 0.1745;

/// The harmonics of a rotary axis's angle tried as error motions: 1 to 4 per revolution (a
/// worm gear's or a bearing's once- and twice-per-revolution errors and the next two; higher
/// orders are a cyclic error's, at ballbar rates a few samples per period).
pub(crate) const ROTARY_HARMONICS: [u32; 4] = [1, 2, 3, 4];

/// Decay times tried for reversal spikes, ms (domain brief: 20-150 ms), a factor of two
/// apart: the profile is refined between them by a parabola. Few, since a spike's shape is a
/// second non-linear parameter and three columns: each grid point costs what three of the
/// other candidates do.
pub const SPIKE_TAU_MS: [f64; 4] = [15.0, 30.0, 60.0, 120.0];

/// Ringing frequencies tried for reversal spikes, Hz (0: no ringing), refined like the decay
/// time (linearly). A real machine's spikes (the shared file) ring at 6-15 Hz, a servo loop's
/// damped mode.
pub(crate) const SPIKE_RING_HZ: [f64; 3] = [0.0, 8.0, 16.0];

/// Speeds tried for stick-slip, mm/min.
pub const STICK_SLIP_MM_PER_MIN: [f64; 4] = [40.0, 80.0, 160.0, 320.0];

/// Time constants tried for the saturating thermal growth of an axis, minutes (a ball screw
/// warms with 10-60 min), a factor of two apart, refined by a parabola on a log scale; the
/// linear growth is the limit of long ones and a candidate of its own.
pub const GROWTH_TAU_MIN: [f64; 4] = [10.0, 20.0, 40.0, 80.0];

/// A session must span this long (from the first run's start to the last's) for thermal
/// growth to be tried: over a shorter one a growth is each run's scale, which the folds cannot
/// tell from the base's, s.
pub(crate) const GROWTH_MIN_SPAN_S: f64 = 600.0;

/// Exponents of the feed tried for an effect whose size grows with the feed (where the runs
/// have two feeds or more): `(F/F_ref)^p` times a spike's or a stick-slip's columns; `p = 0` is
/// the effect itself. A friction spike's height grows with the feed roughly as the servo
/// error's (p ≈ 1), a following error's sharper shape more steeply.
pub const FEED_EXPONENTS: [f64; 3] = [0.5, 1.0, 2.0];

/// Cyclic pitches searched, mm (domain brief: 5-20 mm).
pub const CYCLIC_PITCH_MM: Range<f64> = 2.0..40.0;

/// Vibration frequencies searched: from [`localise::LINE_MIN_HZ`] (below lie a circle's low
/// harmonics and the broad spectra of reversal spikes and stick-slip) to this share of the
/// Nyquist frequency.
pub(crate) const VIBRATION_MAX_NYQUIST: f64 = 0.9;

/// The candidate library for a base model on these runs (cyclic errors come from
/// [`cyclic_candidates`]).
pub fn library(model: &Model, runs: &[Run]) -> Vec<Effect> {
    let axes: Vec<Axis> = model.chain.axes().into_iter().filter(|a| !a.is_rotary()).collect();
    let ids: Vec<String> = model.parameters().into_iter().map(|p| p.id).collect();
    let has = |id: &str| ids.iter().any(|x| x == id);
    let mut out = Vec::new();
    let mut feeds: Vec<f64> = runs.iter().map(|r| r.header.feed_mm_per_min).collect();
    feeds.sort_by(f64::total_cmp);
    feeds.dedup();
    // Sizes that grow with the feed, stated at the lowest feed.
    let scaled = |e: Effect| -> Vec<Effect> {
        if feeds.len() < 2 {
            return vec![e];
        }
        std::iter::once(e.clone())
            .chain(FEED_EXPONENTS.iter().map(|&p| Effect::FeedScaled {
                effect: Box::new(e.clone()),
                exponent: p,
                reference_mm_per_min: feeds[0],
            }))
            .collect()
    };
    let starts = runs.iter().map(|r| r.header.started_at_unix_s);
    let span =
        starts.clone().fold(f64::NEG_INFINITY, f64::max) - starts.fold(f64::INFINITY, f64::min);
    for &a in &axes {
        // The spike's shape is profiled with one set of coefficients for both reversals (the
        // shape is what the grid chooses); the effect tried and fitted has a set per side.
        for tau in SPIKE_TAU_MS {
            for f in SPIKE_RING_HZ {
                out.extend(scaled(Effect::ReversalTransient {
                    axis: a,
                    tau_ms: tau,
                    period_ms: ring_period_ms(f),
                    per_side: false,
                }));
            }
        }
        for v in STICK_SLIP_MM_PER_MIN {
            out.extend(scaled(Effect::StickSlip { axis: a, speed_mm_per_min: v }));
        }
        out.push(Effect::ThermalDrift { axis: Some(a) });
        if span >= GROWTH_MIN_SPAN_S {
            out.push(Effect::ThermalGrowth { axis: a, time_constant_min: None });
            for t in GROWTH_TAU_MIN {
                out.push(Effect::ThermalGrowth { axis: a, time_constant_min: Some(t) });
            }
        }
        for degree in [3, 4] {
            if !has(&format!("E{a}{a}{degree}")) {
                out.push(Effect::PositionalHigherOrder { axis: a, degree });
            }
        }
        for &b in &axes {
            if b != a {
                out.push(Effect::LateralPlay { axis: a, switched_by: b });
                if !has(&format!("E{b}{a}3")) {
                    out.push(Effect::StraightnessHigherOrder { axis: a, toward: b, degree: 3 });
                }
            }
        }
        for about in Axis::LINEAR {
            let rot = ["A", "B", "C"][about.index()];
            if !has(&format!("E{rot}{a}1")) {
                out.push(Effect::AngularError { axis: a, about });
            }
        }
        if !has(&format!("B{a}")) {
            out.push(Effect::Backlash { axis: a });
        }
    }
    // The rotary axes that turn in some run: their error motions beyond location, as
    // harmonics of the angle (ISO 230-7): the angular positioning error, radial and axial
    // run-out and wobble, and their backlash and servo lag. (Their location errors are the
    // base model's.)
    for k in model.chain.axes().into_iter().filter(|a| a.is_rotary()) {
        let turns = runs.iter().any(|r| {
            r.axis(k).is_some_and(|c| {
                c.iter().fold(f64::NEG_INFINITY, |m, &x| m.max(x))
                    - c.iter().fold(f64::INFINITY, |m, &x| m.min(x))
                    > ROTARY_TURNS_RAD
            })
        });
        if !turns {
            continue;
        }
        let own = Axis::LINEAR[k.index() - 3];
        for harmonic in ROTARY_HARMONICS {
            if !has(&format!("E{k}{k}_S{harmonic}")) {
                out.push(Effect::RotaryPositioning { axis: k, harmonic });
            }
            for direction in Axis::LINEAR {
                if !has(&format!("E{direction}{k}_S{harmonic}")) {
                    out.push(Effect::RotaryRunout { axis: k, direction, harmonic });
                }
                let about = Axis::ALL[3 + direction.index()];
                if direction != own && !has(&format!("E{about}{k}_S{harmonic}")) {
                    out.push(Effect::RotaryWobble { axis: k, about, harmonic });
                }
            }
        }
        if !has(&format!("B{k}")) {
            out.push(Effect::Backlash { axis: k });
        }
        if !has(&format!("T{k}")) {
            out.push(Effect::RotaryLag { axis: k });
        }
    }
    out.push(Effect::ThermalDrift { axis: None });
    out.push(Effect::ServoRadiusLoss);
    // Each run's own bar length: with two runs or more, their differences are outside the
    // base (one bar for all runs, or a common scale at one radius, holds their mean).
    if runs.len() >= 2 {
        out.push(Effect::BarLengthDrift);
    }
    if !has("BAR") {
        out.push(Effect::BarLength);
    }
    let planes: Vec<Plane> =
        Plane::PLANAR.into_iter().filter(|p| runs.iter().any(|r| r.header.plane == *p)).collect();
    for p in planes {
        if !has(&format!("M{}", p.name())) {
            out.push(Effect::ServoMismatch { plane: p });
        }
    }
    out
}

/// Cyclic-error candidates: per axis, the two largest peaks of the periodogram of the base
/// residual against the axis's absolute position, `|Σ r û e^{-2πi q/p}|²` over pitches
/// `p` in [`CYCLIC_PITCH_MM`] (wavenumber step a quarter of the inverse axis span, so no peak
/// falls between grid points), refined by a parabola through the peak's neighbours. Also the
/// largest peak per axis as the gap's spectrum against axis position: its amplitude is
/// `2 |Σ r û e^{-2πi q/p}| / Σ û²`, that of a ripple `A sin(2π q/p + φ)` along the axis.
pub fn cyclic_candidates(
    model: &Model,
    runs: &[Run],
    residuals: &[Vec<f64>],
) -> (Vec<Effect>, Vec<localise::PositionPeak>) {
    let mut out = Vec::new();
    let mut spectrum = Vec::new();
    for a in linear_axes(model) {
        let (effects, peak) = cyclic_axis(a, runs, residuals);
        out.extend(effects);
        spectrum.extend(peak);
    }
    (out, spectrum)
}

/// The linear axes of the chain, in the chain's order: the axes the cyclic and vibration
/// candidates are sought along.
pub(crate) fn linear_axes(model: &Model) -> Vec<Axis> {
    model.chain.axes().into_iter().filter(|a| !a.is_rotary()).collect()
}

/// [`cyclic_candidates`] along one axis: its candidates and its largest peak.
pub(crate) fn cyclic_axis(
    a: Axis,
    runs: &[Run],
    residuals: &[Vec<f64>],
) -> (Vec<Effect>, Option<localise::PositionPeak>) {
    let mut out = Vec::new();
    let mut spectrum = None;
    // Samples where the axis moves, with û_a = d_a/|d| of the commanded path.
    let mut q = Vec::new();
    let mut wr = Vec::new();
    let mut uu = 0.0;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (run, r) in runs.iter().zip(residuals) {
        let Some(col) = run.axis(a) else { continue };
        let (cmin, cmax) =
            col.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
        if cmax - cmin < 1.0 {
            continue;
        }
        lo = lo.min(cmin);
        hi = hi.max(cmax);
        let p = run.header.pivot_mm;
        // Every second sample: the axis moves < 0.2 mm between them at ≤ 3000 mm/min and
        // 250 Hz, far below the shortest pitch searched.
        for i in (0..run.len()).step_by(2) {
            let d: Vec<f64> = (0..3)
                .map(|k| run.axis(Axis::LINEAR[k]).map(|c| c[i] - p[k]).unwrap_or(0.0))
                .collect();
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if n > 0.0 {
                q.push(col[i]);
                wr.push(r[i] * d[a.index()] / n);
                uu += (d[a.index()] / n).powi(2);
            }
        }
    }
    if q.len() < 100 || hi - lo < 1.0 {
        return (Vec::new(), None);
    }
    let span = hi - lo;
    let (kmin, kmax) = (1.0 / CYCLIC_PITCH_MM.end, 1.0 / CYCLIC_PITCH_MM.start);
    let dk = 1.0 / (4.0 * span);
    let nk = ((kmax - kmin) / dk) as usize + 1;
    let mut power = vec![0.0; nk];
    // Per sample, e^{-2πi q k} over the uniform k grid by recurrence. Four samples'
    // recurrences run side by side (independent chains the processor overlaps), each
    // added to the sums in sample order: the same sums, bit for bit, as one at a time.
    let mut re = vec![0.0; nk];
    let mut im = vec![0.0; nk];
    let start = |x: f64| {
        let (s0, c0) = (-std::f64::consts::TAU * x * kmin).sin_cos();
        let (sd, cd) = (-std::f64::consts::TAU * x * dk).sin_cos();
        (c0, s0, cd, sd)
    };
    let mut quads = q.chunks_exact(4).zip(wr.chunks_exact(4));
    for (x, w) in quads.by_ref() {
        let mut st: [(f64, f64, f64, f64); 4] = std::array::from_fn(|l| start(x[l]));
        for j in 0..nk {
            let (mut rj, mut ij) = (re[j], im[j]);
            for (l, (c, s, cd, sd)) in st.iter_mut().enumerate() {
                rj += w[l] * *c;
                ij += w[l] * *s;
                let nc = *c * *cd - *s * *sd;
                *s = *s * *cd + *c * *sd;
                *c = nc;
            }
            (re[j], im[j]) = (rj, ij);
        }
    }
    let tail = q.len() - q.len() % 4;
    for (&x, &w) in q[tail..].iter().zip(&wr[tail..]) {
        let (mut c, mut s, cd, sd) = start(x);
        for j in 0..nk {
            re[j] += w * c;
            im[j] += w * s;
            let nc = c * cd - s * sd;
            s = s * cd + c * sd;
            c = nc;
        }
    }
    for j in 0..nk {
        power[j] = re[j] * re[j] + im[j] * im[j];
    }
    let mut peaks: Vec<usize> =
        (1..nk - 1).filter(|&j| power[j] > power[j - 1] && power[j] >= power[j + 1]).collect();
    peaks.sort_by(|&x, &y| power[y].total_cmp(&power[x]));
    for (n, &j) in peaks.iter().take(2).enumerate() {
        // Parabola through the peak and its neighbours.
        let (l, c, r) = (power[j - 1], power[j], power[j + 1]);
        let den = l - 2.0 * c + r;
        let off = if den < 0.0 { (0.5 * (l - r) / den).clamp(-0.5, 0.5) } else { 0.0 };
        let k = kmin + (j as f64 + off) * dk;
        out.push(Effect::CyclicError { axis: a, pitch_mm: 1.0 / k });
        if n == 0 && uu > 0.0 {
            spectrum = Some(localise::PositionPeak {
                axis: a.name().to_string(),
                pitch_mm: 1.0 / k,
                amplitude_um: 2.0 * c.sqrt() / uu * 1e3,
            });
        }
    }
    (out, spectrum)
}

/// A column of a candidate model: a machine column (chain or reading term), or a run term
/// (one column per run).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum ColRef {
    Machine(usize),
    RunTerm(usize),
}

/// A model of candidate columns, the columns of each effect, and the effects.
pub(crate) type Candidates = (Model, Vec<Vec<ColRef>>, Vec<Effect>);

/// One model holding the columns of `effects` alone (a machine without terms, options that add
/// no reading terms): the model, the columns of each effect that could be built on the
/// machine (chain terms first, then reading terms; run terms apart), and those effects.
pub(crate) fn candidate_model(
    bare: &MachineSpec,
    bare_options: ModelOptions,
    kernels: &dyn KernelSource,
    effects: &[Effect],
) -> Result<Candidates, ModelError> {
    let mut all = Model::with_kernels(bare.clone(), bare_options, kernels)?;
    // (0 chain term, 1 reading term, 2 run term, 3 run reading term; index among its kind).
    let mut columns: Vec<Vec<(u8, usize)>> = Vec::new();
    let mut usable: Vec<Effect> = Vec::new();
    let (mut terms, mut readings, mut run_terms) = (Vec::new(), Vec::new(), Vec::new());
    let mut run_readings = Vec::new();
    for e in effects {
        let one =
            match Model::with_effects(bare.clone(), bare_options, kernels, std::slice::from_ref(e))
            {
                Ok(m) => m,
                Err(_) => continue,
            };
        let (t0, r0, u0, v0) = (terms.len(), readings.len(), run_terms.len(), run_readings.len());
        terms.extend(one.terms.iter().cloned());
        readings.extend(one.reading_terms.iter().cloned());
        run_terms.extend(one.run_terms.iter().cloned());
        run_readings.extend(one.run_reading_terms.iter().cloned());
        let cols = (t0..terms.len())
            .map(|x| (0, x))
            .chain((r0..readings.len()).map(|x| (1, x)))
            .chain((u0..run_terms.len()).map(|x| (2, x)))
            .chain((v0..run_readings.len()).map(|x| (3, x)));
        columns.push(cols.collect());
        usable.push(e.clone());
    }
    // Machine column positions: the chain terms, then the reading terms; a run's own: its
    // run terms' coefficients, then its run reading terms'.
    let (n_terms, n_run_terms) = (terms.len(), run_terms.len());
    let place = |(kind, x): (u8, usize)| match kind {
        0 => ColRef::Machine(x),
        1 => ColRef::Machine(n_terms + x),
        2 => ColRef::RunTerm(x),
        _ => ColRef::RunTerm(n_run_terms + x),
    };
    let columns = columns.into_iter().map(|cols| cols.into_iter().map(place).collect()).collect();
    all.terms = terms;
    all.reading_terms = readings;
    all.run_terms = run_terms;
    all.run_reading_terms = run_readings;
    Ok((all, columns, usable))
}

/// The candidate columns of a design of a candidate model (its machine columns, then each
/// run's run-term columns; not the centring, which belongs to the base) and each effect's
/// columns as indices into them.
pub(crate) fn candidate_columns(
    design: &Design<'_>,
    refs: &[Vec<ColRef>],
) -> (Vec<usize>, Vec<Vec<usize>>) {
    let n_rt = design.model.run_terms.len() + design.model.run_reading_terms.len();
    let n_runs = design.runs.len();
    let cand: Vec<usize> =
        (0..design.n_machine).chain((0..n_runs).flat_map(|r| design.run_term_columns(r))).collect();
    let columns = refs
        .iter()
        .map(|cols| {
            cols.iter()
                .flat_map(|c| match *c {
                    ColRef::Machine(j) => vec![j],
                    ColRef::RunTerm(k) => {
                        (0..n_runs).map(|r| design.n_machine + r * n_rt + k).collect()
                    }
                })
                .collect()
        })
        .collect();
    (cand, columns)
}

/// The sampling rate of the runs, Hz: the median over runs of (samples - 1)/duration.
pub fn sample_rate(runs: &[Run]) -> f64 {
    let mut rates: Vec<f64> = runs.iter().filter_map(Run::sample_rate_hz).collect();
    rates.sort_by(f64::total_cmp);
    rates.get(rates.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Vibration candidates: per axis, the two largest peaks of the power spectrum against time of
/// the base residual seen along the axis, `r û_a`, summed over runs (each run's phase is its
/// own: powers add, amplitudes would not), from [`localise::LINE_MIN_HZ`] to
/// [`VIBRATION_MAX_NYQUIST`] of the Nyquist frequency; each refined by a parabola through its
/// neighbours. The FFT is zero-padded at least twice, so the bin step is at most half of
/// 1/(run duration) and a peak lies within half a step of the grid.
pub fn vibration_candidates(model: &Model, runs: &[Run], residuals: &[Vec<f64>]) -> Vec<Effect> {
    let Some(grid) = VibrationGrid::of(runs) else { return vec![] };
    linear_axes(model).into_iter().flat_map(|a| vibration_axis(&grid, a, runs, residuals)).collect()
}

/// The frequency grid of [`vibration_candidates`], the same for every axis.
pub(crate) struct VibrationGrid {
    /// The FFT's length (zero-padded).
    size: usize,
    /// Its bin step, Hz.
    df: f64,
    /// The bins searched.
    k0: usize,
    k1: usize,
    /// The highest circle frequency of the runs, Hz (feed over circumference).
    f_circle: f64,
    /// The runs' sampling rate, Hz.
    rate: f64,
}

impl VibrationGrid {
    /// `None` where the runs are too short, or their rate unknown, for a spectrum.
    pub(crate) fn of(runs: &[Run]) -> Option<VibrationGrid> {
        let rate = sample_rate(runs);
        let longest = runs.iter().map(Run::len).max().unwrap_or(0);
        if !rate.is_finite() || longest < 64 {
            return None;
        }
        let size = (2 * longest).next_power_of_two();
        let df = rate / size as f64;
        let (k0, k1) = (
            (localise::LINE_MIN_HZ / df).ceil() as usize,
            ((VIBRATION_MAX_NYQUIST * rate / 2.0) / df).floor() as usize,
        );
        if k1 <= k0 + 2 {
            return None;
        }
        let f_circle = runs
            .iter()
            .map(|r| r.header.feed_mm_per_s() / (std::f64::consts::TAU * r.header.radius_mm))
            .fold(0.0, f64::max);
        Some(VibrationGrid { size, df, k0, k1, f_circle, rate })
    }
}

/// [`vibration_candidates`] along one axis.
pub(crate) fn vibration_axis(
    grid: &VibrationGrid,
    a: Axis,
    runs: &[Run],
    residuals: &[Vec<f64>],
) -> Vec<Effect> {
    let &VibrationGrid { size, df, k0, k1, f_circle, rate } = grid;
    let mut out = Vec::new();
    let (mut re, mut im) = (vec![0.0; size], vec![0.0; size]);
    let mut power = vec![0.0; k1 + 2];
    let mut used = 0;
    for (run, r) in runs.iter().zip(residuals) {
        let Some(col) = run.axis(a) else { continue };
        let Some(own_rate) = run.sample_rate_hz() else { continue };
        let (lo, hi) =
            col.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
        // Runs at another rate would put their peaks in other bins; runs where the axis
        // stands still do not see it.
        if (own_rate / rate - 1.0).abs() > 1e-3 || hi - lo < 1.0 {
            continue;
        }
        let p = run.header.pivot_mm;
        re.fill(0.0);
        im.fill(0.0);
        for i in 0..run.len() {
            let d: Vec<f64> = (0..3)
                .map(|k| run.axis(Axis::LINEAR[k]).map(|c| c[i] - p[k]).unwrap_or(0.0))
                .collect();
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if n > 0.0 {
                re[i] = r[i] * d[a.index()] / n;
            }
        }
        localise::fft(&mut re, &mut im);
        for (k, pw) in power.iter_mut().enumerate() {
            *pw += re[k] * re[k] + im[k] * im[k];
        }
        used += 1;
    }
    if used == 0 {
        return out;
    }
    let mut peaks: Vec<usize> =
        (k0.max(1)..=k1).filter(|&k| power[k] > power[k - 1] && power[k] >= power[k + 1]).collect();
    peaks.sort_by(|&x, &y| power[y].total_cmp(&power[x]));
    // Seen along the axis, a line is modulated by û twice (the error's direction and the
    // bar's), which puts sidebands at ±2 circle frequencies: a second candidate must lie
    // beyond them (and two bins) from the first, or it is the first again.
    let guard = (2.0 * f_circle / df).ceil() as usize + 2;
    let mut taken: Vec<usize> = Vec::new();
    for &k in &peaks {
        if taken.len() == 2 {
            break;
        }
        if taken.iter().any(|&t| t.abs_diff(k) <= guard) {
            continue;
        }
        taken.push(k);
    }
    for &k in &taken {
        let (l, c, r) = (power[k - 1], power[k], power[k + 1]);
        let den = l - 2.0 * c + r;
        let off = if den < 0.0 { (0.5 * (l - r) / den).clamp(-0.5, 0.5) } else { 0.0 };
        out.push(Effect::Vibration { axis: a, frequency_hz: (k as f64 + off) * df });
    }
    out
}

/// The ringing period (ms) of a ringing frequency (Hz), `None` for none.
pub(crate) fn ring_period_ms(f_hz: f64) -> Option<f64> {
    (f_hz > 0.0).then(|| 1e3 / f_hz)
}

/// The ringing frequency (Hz) of a ringing period (ms), 0 for none.
pub(crate) fn ring_hz(period_ms: Option<f64>) -> f64 {
    period_ms.map(|p| 1e3 / p).unwrap_or(0.0)
}

/// Options of a candidate model: they add no reading terms, so that only the effects' own
/// columns are in it.
pub(crate) const BARE_OPTIONS: ModelOptions = ModelOptions {
    bar_length: ballbar_model::BarLength::Known(0.0),
    servo: ballbar_model::ServoVariant::AxisLag,
};

/// The machine of a candidate model: the chain without terms.
pub(crate) fn bare(spec: &MachineSpec) -> MachineSpec {
    MachineSpec { terms: vec![], ..spec.clone() }
}

/// The searches of the residual's spectra behind the cyclic and vibration candidates: per
/// linear axis its periodogram against position ([`cyclic_candidates`]) and its spectrum
/// against time ([`vibration_candidates`]), each a task of its own ([`Searches::run`]), so
/// that a caller runs them on its worker threads beside other work; [`candidates`] gathers
/// them in task order, the order of the serial functions (the same effects whatever the
/// thread count).
pub(crate) struct Searches<'r> {
    axes: Vec<Axis>,
    grid: Option<VibrationGrid>,
    runs: &'r [Run],
    residuals: &'r [Vec<f64>],
}

/// What one of the [`Searches`] found: its candidates, and the axis's largest peak against
/// position (the cyclic searches only).
pub(crate) type Found = (Vec<Effect>, Option<localise::PositionPeak>);

impl<'r> Searches<'r> {
    pub(crate) fn new(model: &Model, runs: &'r [Run], residuals: &'r [Vec<f64>]) -> Searches<'r> {
        Searches { axes: linear_axes(model), grid: VibrationGrid::of(runs), runs, residuals }
    }

    /// The number of tasks: two per linear axis.
    pub(crate) fn len(&self) -> usize {
        2 * self.axes.len()
    }

    /// Task `t`: the cyclic search along axis `t`, then the vibration search along axis
    /// `t - n` (`n` axes).
    pub(crate) fn run(&self, t: usize) -> Found {
        let n = self.axes.len();
        if t < n {
            cyclic_axis(self.axes[t], self.runs, self.residuals)
        } else {
            let v = self
                .grid
                .as_ref()
                .map(|g| vibration_axis(g, self.axes[t - n], self.runs, self.residuals));
            (v.unwrap_or_default(), None)
        }
    }
}

/// The candidates of a diagnosis: the library, the cyclic errors at the peaks of the base
/// residual's periodogram against position (whose largest peaks go into `gap`'s position
/// spectrum), the vibrations at those of its spectrum against time (`found`: every task of
/// [`Searches`], in task order); only the `kinds` asked for, when any are. Without later runs
/// to predict from earlier ones (one cycle of runs, or all at one time) a time-dependent
/// candidate could not be judged on what it claims (the next runs), and interleaved folds
/// would flatter it: it is not offered, and the note returned says so.
pub(crate) fn candidates(
    model: &Model,
    runs: &[Run],
    found: Vec<Found>,
    has_later_runs: bool,
    kinds: &[String],
    gap: &mut localise::Gap,
) -> (Vec<Effect>, Vec<String>) {
    let mut notes = Vec::new();
    let mut effects = library(model, runs);
    if !has_later_runs && effects.iter().any(Effect::is_time_dependent) {
        effects.retain(|e| !e.is_time_dependent());
        notes.push(
            "thermal growth and drift not tried: no runs come after a start of the session that holds every plane in every direction, so nothing could judge them on later runs; repeat the test cycle later to see them"
                .to_string(),
        );
    }
    let mut position_spectrum = Vec::new();
    for (e, peak) in found {
        effects.extend(e);
        position_spectrum.extend(peak);
    }
    gap.position_spectrum = position_spectrum;
    if !kinds.is_empty() {
        effects.retain(|e| kinds.iter().any(|k| k == e.kind()));
    }
    (effects, notes)
}
