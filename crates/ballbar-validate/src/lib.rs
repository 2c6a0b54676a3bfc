//! The diagnosis's validation scenarios, kept apart from the diagnosis so that what judges it
//! is not part of it: each scenario simulates a machine with effects its base model lacks,
//! gives the runs to [`ballbar_diagnose::diagnose`] without any hint, and judges what comes
//! back.
//!
//! - [`suite`]: the first set: each effect simulated with the shape of the candidate that
//!   should find it, by the shared simulator, held out by the diagnosis's own folds and
//!   compared with an oracle (the true effects in the model).
//! - [`independent`]: the second set, kept apart from the first: physical effects whose
//!   shapes are not the candidates' (thermal growth of a screw, feed-dependent spikes,
//!   Stribeck friction, play with finite stiffness, feed-driven vibration), added by hand to
//!   the simulated base machine, and held-out runs the user would meet next (later in time, or
//!   a feed or centre the training never saw), on which the diagnosis's claimed closure is
//!   measured.

pub mod independent;
pub mod suite;

#[cfg(test)]
mod independent_tests;
#[cfg(test)]
mod tests;
