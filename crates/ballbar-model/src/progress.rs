//! Progress of long work (a fit's runs, a diagnosis's candidates), for a front end that shows
//! it: the computing code reports `(what, done, total)` and knows nothing of terminals. A
//! front end installs one [`Sink`] for the process ([`set_sink`]); without one (a library
//! caller, a test, output that is not a terminal) a report costs an atomic load.

use std::sync::OnceLock;

/// Where progress goes.
pub trait Sink: Send + Sync {
    /// `done` of `total` units of the step `what` are complete (called from any thread).
    fn update(&self, what: &str, done: usize, total: usize);
    /// The work is over: remove what was shown.
    fn finish(&self);
}

static SINK: OnceLock<Box<dyn Sink>> = OnceLock::new();

/// Install the process's sink; `false` if one is installed already (it stays).
pub fn set_sink(sink: Box<dyn Sink>) -> bool {
    SINK.set(sink).is_ok()
}

/// Report progress of the step `what`.
pub fn update(what: &str, done: usize, total: usize) {
    if let Some(s) = SINK.get() {
        s.update(what, done, total);
    }
}

/// The work is over.
pub fn finish() {
    if let Some(s) = SINK.get() {
        s.finish();
    }
}
