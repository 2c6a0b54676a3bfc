//! The diagnosis's validation scenarios, kept apart from the diagnosis so that what judges it
//! is not part of it: each scenario simulates a machine with effects its base model lacks,
//! gives the runs to [`ballbar_diagnose::diagnose`] without any hint, and judges what comes
//! back.
//!
//! - [`suite`]: the first set (issue #4): each effect simulated with the shape of the
//!   candidate that should find it, by the shared simulator, held out by the diagnosis's own
//!   folds and compared with an oracle (the true effects in the model).

pub mod suite;

#[cfg(test)]
mod tests;
