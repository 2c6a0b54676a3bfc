//! Reports of a ballbar session: the fit report ([`fit_report`]: terminal text and the
//! `ballbar-fit/1` JSON) and the self-contained HTML page of an archived session ([`page`]).

pub mod assumed;
pub mod fit_report;
pub mod history;
pub mod page;
mod rotary;
pub mod session_info;
mod svg;
pub mod tolerance;
pub mod vendor;

pub use fit_report::FitReport;
pub use page::{Page, PageOptions, ReportError, build, build_with};

#[cfg(test)]
mod tests;
