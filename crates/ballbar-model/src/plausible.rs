//! The physical bounds of a ballbar test, shared by the readers of runs (`ballbar-io`, which
//! checks every run against them) and the simulator's truth files (`ballbar-sim`): a value
//! beyond them is not a measurement of a machine tool but a wrong unit, a typo or a damaged
//! file, and is refused rather than fitted.

/// The feeds of a contouring test, mm/min (lowest, highest). Below 1 mm/min a circle of 100 mm
/// takes over ten hours, longer than a machine stays thermally still; above 100,000 mm/min
/// (1.7 m/s) lies beyond the contouring feeds of machine tools (their rapid traverses reach
/// 60-120 m/min, but a ballbar test runs at a cutting feed, typically 500-10,000 mm/min).
pub const FEED_MM_PER_MIN: (f64, f64) = (1.0, 100_000.0);

/// The sample rates of a ballbar, Hz (lowest, highest): a QC10 samples at 250 Hz, a QC20 at
/// 1 kHz; below 1 Hz a circle at a typical feed gives fewer samples than the model has
/// terms, and above 100 kHz no displacement sensor used on a ballbar reads.
pub const SAMPLE_RATE_HZ: (f64, f64) = (1.0, 100_000.0);

/// The bar lengths of a ballbar test, mm (shortest, longest): ballbars are 50-600 mm long
/// (extensions reach 1.3 m); 1 mm to 5 m holds every one with a wide margin and no typo of a
/// unit (a length in m or µm).
pub const RADIUS_MM: (f64, f64) = (1.0, 5000.0);

/// The largest reading a ballbar gives, mm: its transducer's range is about ±1 mm around its
/// nominal length. A larger value is the bar's length rather than its deviation, or a wrong
/// unit.
pub const MAX_READING_MM: f64 = 1.0;

/// Readings that all lie within this of the nominal length, µm, are not a real run's: the
/// set-up's centring alone (a few µm at best with a setting tool) and the bar's offset from its
/// calibrated length move a real trace by more, let alone a machine's errors. Readings in mm
/// under a µm column look like this (a real 40 µm reads as 0.04).
pub const MIN_READING_PEAK_UM: f64 = 0.5;

/// Readings that all lie within this, µm, are stated as unusual (a warning): an excellent
/// machine, centred with care, or readings in mm of a poor one.
pub const LOW_READING_PEAK_UM: f64 = 2.0;

/// How far a run's duration may differ from its path over its feed (relative) before it is an
/// error or a warning, once the machine's acceleration is allowed for
/// ([`MIN_ACCELERATION_MM_PER_S2`]): within 5 % is a feed as programmed (a control holds
/// its feed to a per cent, a ballbar's clock to far better); up to a factor of 1.25 beyond that
/// is stated as a warning (a feed override, which controls offer in steps of 5-10 %); beyond,
/// the times or the feed are wrong (t_s in ms, a feed in mm/s, a sample rate off by 2).
pub const DURATION_TOLERANCE: f64 = 0.05;

/// See [`DURATION_TOLERANCE`]: the factor beyond it up to which a duration is a warning.
pub const DURATION_WARNING_FACTOR: f64 = 1.25;

/// The slowest acceleration of a machine tool's axes, mm/s² (0.2 m/s²; large gantries
/// accelerate at 0.5 m/s² and more): a run that starts and stops with its samples takes up to
/// `v/a` longer than its path over its feed `v`.
pub const MIN_ACCELERATION_MM_PER_S2: f64 = 200.0;

/// The largest reading noise a truth file may state, µm (standard deviation): a ballbar's own
/// is about 0.1 µm; at 100 µm the simulated readings already reach the bar's ±1 mm range at
/// 10 σ.
pub const MAX_NOISE_UM: f64 = 100.0;

/// The largest magnitude of a start angle, degrees: one turn either way; a larger value is a
/// typo or an angle in other units.
pub const MAX_START_ANGLE_DEG: f64 = 360.0;
