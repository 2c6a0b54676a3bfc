//! Reports of a ballbar session: the fit report ([`fit_report`]: terminal text and the
//! `ballbar-fit/1` JSON) and the self-contained HTML page of an archived session ([`page`]).

pub mod fit_report;
pub mod page;
mod rotary;
mod svg;
pub mod vendor;

pub use fit_report::FitReport;
pub use page::{build, Page, ReportError};

#[cfg(test)]
mod tests;
