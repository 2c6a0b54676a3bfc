//! How the data are held out: the units of held-out evaluation and the schemes of folds over
//! them, each chosen for what the user will meet next.
//!
//! - **Configurations** (tool length, ball heights, centre, radius, feed: everything of a run's
//!   set-up but its plane and direction), when the runs have more than one: each configuration's
//!   runs predicted from the others. A claim made on these folds is a claim about a set-up the
//!   model was not fitted on, which is what a user changes.
//! - **Repeats** (runs of one set-up repeated): each repeat predicted from the others.
//! - **Cells** (a configuration's runs in one plane), when there are configurations but no
//!   repeats: the fallback for an effect that one configuration alone cannot determine (an
//!   angular error seen through two tool lengths, a radius loss at two feeds): training then
//!   holds the held-out set-up through its other planes, and the other set-ups in this plane.
//! - **Later runs** (forward validation), when the runs were measured at two or more times and
//!   every plane is measured before the last ones: the runs in time order cut into blocks, the
//!   first the shortest start of the session that holds every plane in every direction, the
//!   others half its size (the last may be shorter); each block predicted from the blocks
//!   before it, never from later ones. Half, so that no fold extrapolates further, for the
//!   span it was fitted on, than the model of a session of two cycles or more does when it
//!   predicts the next cycle (at most half its span ahead); a block of the first's size
//!   predicted from the first alone is a whole span ahead. A time-dependent shape (a growth's time constant) that a fold's training cannot
//!   tell from another is then judged over as short a stretch, for what it was fitted on, as
//!   the whole session's model will be used; with blocks of the first's size, a growth of
//!   35 min seen over 0-30 min was judged over 30-60 min with the time constant the first
//!   half hour allowed (80 min; the whole session chose 43), and the claim fell 15 points
//!   short of what the next cycle showed. Every
//!   time-dependent candidate (a thermal growth or drift) is judged on these: its question is
//!   the next runs (extrapolation), which interleaved folds (interpolation) flatter.
//! - **Quarters** of each run, centred on an axis reversal, or **halves**, for one set-up run
//!   once per direction (the shop-floor CW + CCW test; [`sectors`]).
//!
//! - At most [`MAX_FOLDS`] folds of groups: more repeats, configurations or cells are dealt
//!   round into that many, and the later runs are the last ten blocks of a twelfth of the
//!   session each, so that a session of a thousand runs costs ten refits of its training per
//!   candidate, not a thousand.
//!
//! The primary scheme is the first of configurations, repeats, quarters, halves that applies
//! (configurations and cells only when every fold's training holds each plane and direction it
//! predicts: with a centre per plane, a configuration is a plane, which nothing else predicts);
//! a candidate that the training of some fold of it cannot determine (it adds less rank there
//! than on all data) is judged on the secondary scheme (repeats, else cells), or declined as
//! not judgeable. The base model's own combinations that a fold's training cannot determine
//! (a held-out radius, when the bar length rests on two) are not a reason to drop the fold:
//! the evaluation fits them on the held-out runs as nuisances
//! ([`crate::engine::Blocks::held_out_fold`]), and the scheme's description names them.

use std::ops::Range;

use ballbar_model::Run;

use crate::localise;

/// What a scheme holds out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SchemeKind {
    /// Whole configurations.
    Configurations,
    /// Whole repeats.
    Repeats,
    /// A configuration's runs in one plane.
    Cells,
    /// Later runs, from the earlier ones only.
    LaterRuns,
    /// Quarters of runs centred on the reversals.
    Quarters,
    /// Halves of runs.
    Halves,
}

impl SchemeKind {
    /// The name in the diagnosis JSON (`folds`).
    pub fn name(self) -> &'static str {
        match self {
            SchemeKind::Configurations => "configurations",
            SchemeKind::Repeats => "repeats",
            SchemeKind::Cells => "configuration_planes",
            SchemeKind::LaterRuns => "later_runs",
            SchemeKind::Quarters => "quarters",
            SchemeKind::Halves => "halves",
        }
    }
}

/// One scheme of folds over the units: each fold's training and held-out units.
#[derive(Clone, Debug)]
pub struct Scheme {
    /// What it holds out.
    pub kind: SchemeKind,
    /// Why and how, for the report.
    pub description: String,
    /// (training units, held-out units) per fold; no held-out unit is in its fold's training.
    pub folds: Vec<(Vec<usize>, Vec<usize>)>,
}

/// The units of held-out evaluation (run, its samples, the primary fold that holds them out)
/// and the schemes over them.
pub struct Splits {
    /// The units (engine's input).
    pub units: Vec<(usize, Range<usize>, Option<usize>)>,
    /// The primary scheme.
    pub primary: Scheme,
    /// The fallback for candidates the primary's training cannot determine.
    pub secondary: Option<Scheme>,
    /// Later runs from earlier ones, when the session has them.
    pub forward: Option<Scheme>,
}

impl Splits {
    /// The schemes in one list (the primary first), and the positions of the secondary and of
    /// the later runs in it.
    pub fn schemes(&self) -> (Vec<Scheme>, Option<usize>, Option<usize>) {
        let mut out = vec![self.primary.clone()];
        let mut push = |s: &Option<Scheme>| {
            s.clone().map(|s| {
                out.push(s);
                out.len() - 1
            })
        };
        let secondary = push(&self.secondary);
        let forward = push(&self.forward);
        (out, secondary, forward)
    }
}

/// A run's configuration: its set-up but for plane and direction.
fn configuration(run: &Run) -> [i64; 11] {
    let h = &run.header;
    // Micrometres (or 1e-3 mm/min): finer than any set-up is stated, coarser than round-off.
    let q = |x: f64| (x * 1e3).round() as i64;
    [
        q(h.radius_mm),
        q(h.feed_mm_per_min),
        q(h.pivot_mm[0]),
        q(h.pivot_mm[1]),
        q(h.pivot_mm[2]),
        q(h.tool_ball_mm[0]),
        q(h.tool_ball_mm[1]),
        q(h.tool_ball_mm[2]),
        q(h.table_ball_mm[0]),
        q(h.table_ball_mm[1]),
        q(h.table_ball_mm[2]),
    ]
}

/// A free run's path, but for its direction: the range of each axis column (µm, µrad), which a
/// rotary test's CW and CCW runs share and two tests (a radial and a tangential bar at one
/// pivot, another sweep) do not. Empty for a planar run.
fn free_path(run: &Run) -> Vec<(i64, i64)> {
    if run.header.plane != ballbar_model::Plane::Free {
        return Vec::new();
    }
    ballbar_model::Axis::ALL
        .iter()
        .filter_map(|&a| run.axis(a))
        .map(|c| {
            let (lo, hi) = c
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
            ((lo * 1e3).round() as i64, (hi * 1e3).round() as i64)
        })
        .collect()
}

/// What differs between configurations, in words (`feed`, `tool length`, ...).
fn varies(runs: &[Run]) -> String {
    let mut out = Vec::new();
    let h0 = &runs[0].header;
    let any = |f: &dyn Fn(&ballbar_model::RunHeader) -> bool| runs.iter().any(|r| f(&r.header));
    if any(&|h| h.feed_mm_per_min != h0.feed_mm_per_min) {
        out.push("feed");
    }
    if any(&|h| h.radius_mm != h0.radius_mm) {
        out.push("radius");
    }
    if any(&|h| h.pivot_mm != h0.pivot_mm) {
        out.push("centre");
    }
    if any(&|h| h.tool_ball_mm != h0.tool_ball_mm) {
        out.push("tool length");
    }
    if any(&|h| h.table_ball_mm != h0.table_ball_mm) {
        out.push("ball height");
    }
    out.join(", ")
}

/// Group indices by a key, in order of first appearance.
fn groups<K: PartialEq>(n: usize, key: impl Fn(usize) -> K) -> Vec<Vec<usize>> {
    let mut keys: Vec<K> = Vec::new();
    let mut out: Vec<Vec<usize>> = Vec::new();
    for i in 0..n {
        let k = key(i);
        match keys.iter().position(|x| *x == k) {
            Some(g) => out[g].push(i),
            None => {
                keys.push(k);
                out.push(vec![i]);
            }
        }
    }
    out
}

/// True when every fold's training holds each plane, in each direction, that its held-out
/// units hold: otherwise the base model cannot be determined for what it predicts (a
/// plane's squareness and servo mismatch from no run of the plane) and the held-out error
/// measures that, not a candidate. Per-plane centres make every configuration one plane.
fn covers(
    runs: &[Run],
    units: &[(usize, Range<usize>, Option<usize>)],
    folds: &[(Vec<usize>, Vec<usize>)],
) -> bool {
    let key = |u: usize| (runs[units[u].0].header.plane, runs[units[u].0].header.direction);
    !folds.is_empty()
        && folds
            .iter()
            .all(|(train, held)| held.iter().all(|&h| train.iter().any(|&t| key(t) == key(h))))
}

/// The most folds a scheme of groups (repeats, configurations, cells; the later runs' blocks
/// after the first) is cut into. More groups are dealt round into this many folds, the `k`-th
/// holding out groups `k`, `k + 10`, `k + 20`, ...: each fold's training still holds 9 of 11
/// groups at least (a K-fold estimate's pessimism against leaving one group out falls as
/// 1/K, and is a few per cent of a share here), and the diagnosis's work per fold
/// (every fold refits its training, chooses its shapes and screens its gains) stays in
/// proportion to the session instead of to its square: a session of 1,000 runs as 167
/// repeats is 10 folds, not 167.
pub const MAX_FOLDS: usize = 10;

/// `groups` dealt round into at most [`MAX_FOLDS`] (group `g` into `g mod MAX_FOLDS`, in
/// order); fewer are kept as they are.
fn dealt(groups: Vec<Vec<usize>>) -> Vec<Vec<usize>> {
    if groups.len() <= MAX_FOLDS {
        return groups;
    }
    let mut out = vec![Vec::new(); MAX_FOLDS];
    for (g, members) in groups.into_iter().enumerate() {
        out[g % MAX_FOLDS].extend(members);
    }
    out
}

/// The words a scheme's description adds when its `n` groups were dealt into fewer folds
/// ([`dealt`]), else nothing.
fn dealt_words(n: usize, what: &str) -> String {
    if n > MAX_FOLDS {
        format!(
            "; the {n} {what} dealt round, fold k holding out the k-th, the (k + {MAX_FOLDS})-th, ..."
        )
    } else {
        String::new()
    }
}

/// Folds that hold out each group of runs in turn (units by run); more groups than
/// [`MAX_FOLDS`] are dealt round into that many ([`dealt`]).
fn leave_group_out(
    units: &[(usize, Range<usize>, Option<usize>)],
    run_groups: &[Vec<usize>],
) -> Vec<(Vec<usize>, Vec<usize>)> {
    dealt(run_groups.to_vec())
        .iter()
        .map(|g| {
            let (held, train): (Vec<usize>, Vec<usize>) =
                (0..units.len()).partition(|&u| g.contains(&units[u].0));
            (train, held)
        })
        .filter(|(train, held)| !held.is_empty() && !train.is_empty())
        .collect()
}

/// The units and schemes for these runs.
pub fn splits(runs: &[Run]) -> Splits {
    if runs.iter().any(|r| r.header.plane == ballbar_model::Plane::Free)
        && let Some(s) = free_splits(runs)
    {
        return s;
    }
    let configs = groups(runs.len(), |i| configuration(&runs[i]));
    let sets = localise::repeat_sets(runs);
    let has_repeats = sets.iter().any(|s| s.len() >= 2);
    // The repeats: the k-th run of every repeated set together.
    let repeat_groups = || {
        let k = sets.iter().map(Vec::len).max().unwrap_or(0);
        (0..k)
            .map(|i| {
                sets.iter()
                    .filter(|s| s.len() >= 2)
                    .filter_map(|s| s.get(i).copied())
                    .collect::<Vec<usize>>()
            })
            .collect::<Vec<_>>()
    };
    let whole: Vec<(usize, Range<usize>, Option<usize>)> =
        runs.iter().enumerate().map(|(r, run)| (r, 0..run.len(), None)).collect();
    let config_folds = leave_group_out(&whole, &configs);
    let (units, primary, secondary) = if configs.len() >= 2 && covers(runs, &whole, &config_folds) {
        let folds = config_folds;
        let primary = Scheme {
            kind: SchemeKind::Configurations,
            description: format!(
                "each configuration predicted from the others ({} folds of whole runs; the runs differ in {}{})",
                folds.len(),
                varies(runs),
                dealt_words(configs.len(), "configurations")
            ),
            folds,
        };
        let secondary = if has_repeats {
            let groups = repeat_groups();
            let folds = leave_group_out(&whole, &groups);
            Some(Scheme {
                kind: SchemeKind::Repeats,
                description: format!(
                    "leave one repeat out ({} folds of whole runs{})",
                    folds.len(),
                    dealt_words(groups.len(), "repeats")
                ),
                folds,
            })
        } else {
            let cells = groups(runs.len(), |i| (configuration(&runs[i]), runs[i].header.plane));
            let folds = leave_group_out(&whole, &cells);
            covers(runs, &whole, &folds).then(|| Scheme {
                kind: SchemeKind::Cells,
                description: format!("each configuration's runs in one plane predicted from the rest ({} folds of whole runs{})", folds.len(), dealt_words(cells.len(), "cells")),
                folds,
            })
        };
        (whole.clone(), primary, secondary)
    } else if has_repeats {
        let groups = repeat_groups();
        let folds = leave_group_out(&whole, &groups);
        (
            whole.clone(),
            Scheme {
                kind: SchemeKind::Repeats,
                description: format!(
                    "leave one repeat out ({} folds of whole runs{})",
                    folds.len(),
                    dealt_words(groups.len(), "repeats")
                ),
                folds,
            },
            None,
        )
    } else if let Some((units, n)) = sectors(runs) {
        let folds = (0..n)
            .map(|f| (0..units.len()).partition::<Vec<usize>, _>(|&u| units[u].2 != Some(f)))
            .filter(|(_, h): &(Vec<usize>, Vec<usize>)| !h.is_empty())
            .collect();
        let s = Scheme {
            kind: SchemeKind::Quarters,
            description: format!(
                "one set-up, run once per direction: each quarter of each run, centred on an axis reversal, predicted from the rest ({n} folds)"
            ),
            folds,
        };
        (units, s, None)
    } else {
        let mut units = Vec::new();
        for (r, run) in runs.iter().enumerate() {
            let h = run.len() / 2;
            units.push((r, 0..h, Some(0)));
            units.push((r, h..run.len(), Some(1)));
        }
        let folds = (0..2)
            .map(|f| (0..units.len()).partition::<Vec<usize>, _>(|&u| units[u].2 != Some(f)))
            .collect();
        (units, Scheme { kind: SchemeKind::Halves, description: "one set-up, run once per direction: first halves of the runs against second halves".into(), folds }, None)
    };
    let forward = forward(runs, &units);
    Splits { units: number_primary(units, &primary), primary, secondary, forward }
}

/// The units and schemes of a session with free (rotary) runs: every run cut into quarters (a
/// planar run's centred on the reversals, [`sectors`]; a rotary run's the four equal parts of
/// the sweep of the axis that turns furthest), so that a fold can hold out part of a run;
/// configurations are the set-ups and, for rotary runs, the tests (a radial and a tangential
/// bar at one pivot are two). The primary is configurations (whole runs), else repeats, else
/// the quarters; the secondary the repeats, else the quarters: an error motion that one
/// rotary test alone sees (the angular positioning error of C, in the tangential runs) cannot
/// be learned when that test is held out whole, and is judged on the quarters of the runs.
/// `None` when a run can be cut neither way.
fn free_splits(runs: &[Run]) -> Option<Splits> {
    let (units, n) = sectors(runs)?;
    let configs = groups(runs.len(), |i| (configuration(&runs[i]), free_path(&runs[i])));
    let sets = localise::repeat_sets(runs);
    let has_repeats = sets.iter().any(|s| s.len() >= 2);
    let repeat_groups = || {
        let k = sets.iter().map(Vec::len).max().unwrap_or(0);
        (0..k)
            .map(|i| {
                sets.iter()
                    .filter(|s| s.len() >= 2)
                    .filter_map(|s| s.get(i).copied())
                    .collect::<Vec<usize>>()
            })
            .collect::<Vec<_>>()
    };
    let config_folds = leave_group_out(&units, &configs);
    let quarters = || {
        let folds: Vec<(Vec<usize>, Vec<usize>)> = (0..n)
            .map(|f| (0..units.len()).partition::<Vec<usize>, _>(|&u| units[u].2 != Some(f)))
            .filter(|(_, h): &(Vec<usize>, Vec<usize>)| !h.is_empty())
            .collect();
        Scheme {
            kind: SchemeKind::Quarters,
            description: format!(
                "each quarter of each run (a planar run's centred on a reversal, a rotary run's a quarter of its sweep) predicted from the rest ({} folds)",
                folds.len()
            ),
            folds,
        }
    };
    let repeats = || {
        let groups = repeat_groups();
        let folds = leave_group_out(&units, &groups);
        Scheme {
            kind: SchemeKind::Repeats,
            description: format!(
                "leave one repeat out ({} folds of whole runs{})",
                folds.len(),
                dealt_words(groups.len(), "repeats")
            ),
            folds,
        }
    };
    let (primary, secondary) = if configs.len() >= 2 && covers(runs, &units, &config_folds) {
        let primary = Scheme {
            kind: SchemeKind::Configurations,
            description: format!(
                "each configuration (set-up, and for rotary runs the test) predicted from the others ({} folds of whole runs{})",
                config_folds.len(),
                dealt_words(configs.len(), "configurations")
            ),
            folds: config_folds,
        };
        (primary, Some(if has_repeats { repeats() } else { quarters() }))
    } else if has_repeats {
        (repeats(), Some(quarters()))
    } else {
        (quarters(), None)
    };
    // Each unit's primary fold is set by `number_primary` (the sectors' own numbering is the
    // quarters scheme's, which may not be the primary).
    let forward = forward(runs, &units);
    Some(Splits { units: number_primary(units, &primary), primary, secondary, forward })
}

/// The units with the primary fold that holds each out.
fn number_primary(
    mut units: Vec<(usize, Range<usize>, Option<usize>)>,
    primary: &Scheme,
) -> Vec<(usize, Range<usize>, Option<usize>)> {
    for (u, unit) in units.iter_mut().enumerate() {
        unit.2 = primary.folds.iter().position(|(_, held)| held.contains(&u));
    }
    units
}

/// Later runs from earlier ones: the runs in time order cut into blocks, the first the
/// shortest start of the session that holds every plane in every direction (so that the base
/// model is determined from it), the others half its size, rounded up (the last may be
/// shorter; why half: the module's documentation). Where those would be more than
/// [`MAX_FOLDS`], the last `MAX_FOLDS` blocks of a twelfth of the session each, every one
/// predicted from at least twice its size, and the first block all before them. `None` when
/// that start is the whole session, or the runs all start at one time.
fn forward(runs: &[Run], units: &[(usize, Range<usize>, Option<usize>)]) -> Option<Scheme> {
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by(|&a, &b| {
        runs[a]
            .header
            .started_at_unix_s
            .total_cmp(&runs[b].header.started_at_unix_s)
            .then(a.cmp(&b))
    });
    let first_t = runs[order[0]].header.started_at_unix_s;
    if order.iter().all(|&r| runs[r].header.started_at_unix_s == first_t) {
        return None;
    }
    // Every plane in every direction: one direction alone cannot tell the direction-odd terms
    // (servo mismatch, backlash) from the even ones.
    let key = |r: usize| (runs[r].header.plane, runs[r].header.direction);
    let mut planes: Vec<_> = Vec::new();
    for r in 0..runs.len() {
        if !planes.contains(&key(r)) {
            planes.push(key(r));
        }
    }
    let mut seen = Vec::new();
    let mut size = order.len();
    for (k, &r) in order.iter().enumerate() {
        if !seen.contains(&key(r)) {
            seen.push(key(r));
        }
        if seen.len() == planes.len() {
            size = k + 1;
            break;
        }
    }
    // The first block, then blocks of half its size (the remainder a block of its own). When
    // those would be more than `MAX_FOLDS`: the last `MAX_FOLDS` blocks of ⌊n/12⌋ runs, each
    // predicted from at least twice its size (the first block, n − 10⌊n/12⌋ ≥ n/6 runs,
    // holds the shortest start: n > size + 10⌈size/2⌉ ≥ 6·size).
    let n = order.len();
    let half = size.div_ceil(2);
    let (first, later) = if n - size <= MAX_FOLDS * half {
        (size, half)
    } else {
        let b = n / (MAX_FOLDS + 2);
        (n - MAX_FOLDS * b, b)
    };
    let n_later = (n - first).div_ceil(later);
    if n_later == 0 {
        return None;
    }
    let mut block = vec![0; runs.len()];
    for (pos, &r) in order.iter().enumerate() {
        block[r] = if pos < first { 0 } else { 1 + (pos - first) / later };
    }
    let folds: Vec<(Vec<usize>, Vec<usize>)> = (1..=n_later)
        .map(|b| {
            let train = (0..units.len()).filter(|&u| block[units[u].0] < b).collect();
            let held = (0..units.len()).filter(|&u| block[units[u].0] == b).collect();
            (train, held)
        })
        .collect();
    let last = n - first - (n_later - 1) * later;
    let first_words = if first == size {
        format!(
            "the first the shortest start of the session that holds every plane in every direction ({size} runs)"
        )
    } else {
        format!(
            "the first {first} runs (the shortest start that holds every plane in every direction is {size})"
        )
    };
    let later_words = match (n_later, last == later) {
        (1, _) => format!("then one of {last} runs"),
        (k, true) => format!("then {k} of {later} runs"),
        (k, false) => format!("then {} of {later} runs and one of {last}", k - 1),
    };
    Some(Scheme {
        kind: SchemeKind::LaterRuns,
        description: format!(
            "later runs predicted from the earlier ones only ({} blocks in time order, {first_words}, {later_words}; {} fold{})",
            n_later + 1,
            folds.len(),
            if folds.len() == 1 { "" } else { "s" }
        ),
        folds,
    })
}

/// Run `r` cut where its samples' quarter (`quarter[i]`) changes: one unit per stretch, in the
/// fold of its (run, quarter), numbered in order of first appearance.
#[allow(clippy::type_complexity)]
fn cut(
    r: usize,
    quarter: &[usize],
    units: &mut Vec<(usize, Range<usize>, Option<usize>)>,
    folds: &mut Vec<(usize, usize)>,
) {
    let mut start = 0;
    while start < quarter.len() {
        let q = quarter[start];
        let mut end = start + 1;
        while end < quarter.len() && quarter[end] == q {
            end += 1;
        }
        let fold = folds.iter().position(|f| *f == (r, q)).unwrap_or_else(|| {
            folds.push((r, q));
            folds.len() - 1
        });
        units.push((r, start..end, Some(fold)));
        start = end;
    }
}

/// Folds of planar runs without repeats at one set-up (a single-plane CW + CCW test, the common
/// shop-floor case): each run cut into the four quarters of the circle centred on the in-plane
/// axes' reversals (0°, 90°, 180°, 270°), and each quarter of each run one fold, predicted from
/// everything else: the units (run, samples, fold) and the number of folds. `None` when a run
/// is not planar.
///
/// Why not the alternatives a two-run test seems to offer:
/// - CW against CCW: a model fitted on one direction cannot tell the direction-odd terms
///   (servo mismatch, backlash) from the direction-even ones they resemble within a run
///   (squareness, the centring); its prediction of the other direction is then as wrong as
///   that arbitrary split, and the held-out error measures the base's aliasing, not the
///   candidate.
/// - First halves against second halves: each half holds whole reversals in one direction
///   only (in a CCW run from 180°, the first half has Y's reversal at 270° and the second its
///   reversal at 90° and X's at 0°), so an effect of one side of one axis is in one fold only
///   and cannot be learned for it; and the base is extrapolated over half a circle.
///
/// With quarters, the training data of every fold hold every angle in at least one
/// direction, every reversal but one in both, and the held-out reversal in the other
/// direction: the base is fitted on seven eighths of the data (two runs) with every angle in
/// it, and an effect at a reversal is learned from the same reversal run the other way and
/// from the axis's other reversal. The held-out quarter's samples are used for nothing in its
/// fold (the run's centring comes from its other quarters); only the noise's correlation
/// reaches across its ends, over a few samples of a few hundred.
#[allow(clippy::type_complexity)]
fn sectors(runs: &[Run]) -> Option<(Vec<(usize, Range<usize>, Option<usize>)>, usize)> {
    let mut units = Vec::new();
    let mut folds: Vec<(usize, usize)> = Vec::new();
    for (r, run) in runs.iter().enumerate() {
        if run.header.plane == ballbar_model::Plane::Free {
            // A rotary run: the four equal parts of the sweep of the axis that turns furthest.
            let turning = ballbar_model::Axis::ALL
                .iter()
                .filter(|a| a.is_rotary())
                .filter_map(|&a| run.axis(a))
                .map(|c| {
                    (
                        c.iter().fold(f64::INFINITY, |m, &x| m.min(x)),
                        c.iter().fold(f64::NEG_INFINITY, |m, &x| m.max(x)),
                        c,
                    )
                })
                .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)))?;
            let (lo, hi, col) = turning;
            if hi - lo <= 0.0 {
                return None;
            }
            let quarter: Vec<usize> = col
                .iter()
                .map(|&x| (((x - lo) / (hi - lo) * 4.0).floor() as usize).min(3))
                .collect();
            cut(r, &quarter, &mut units, &mut folds);
            continue;
        }
        let theta = ballbar_fit::metrics::angles(run)?;
        let quarter: Vec<usize> = theta
            .iter()
            .map(|&t| ((t / std::f64::consts::FRAC_PI_2).round() as i64).rem_euclid(4) as usize)
            .collect();
        cut(r, &quarter, &mut units, &mut folds);
    }
    let n = folds.len();
    Some((units, n))
}
