//! The progress bar of long work on a terminal: one line on standard error, `what [####....]
//! 45 %, about 0:12 left`, redrawn at most ten times a second and cleared when the work is
//! over. Installed only when standard error is a terminal ([`install`]): never in pipes, files,
//! JSON output or tests. Standard library only: a line of text needs no crate.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Redraws at most this often: ten a second is smooth to the eye and costs nothing.
const REDRAW: Duration = Duration::from_millis(100);

/// Width of the bar, characters (the whole line stays under 80 columns for a step name of up
/// to 40).
const BAR: usize = 20;

/// The line for a step `what` that is `fraction` (0 to 1) done after `elapsed`: the time left
/// is estimated as `elapsed (1 - f) / f` (the rate so far held), shown once a hundredth is
/// done (before that the rate says nothing).
pub fn render(what: &str, fraction: f64, elapsed: Duration) -> String {
    let f = if fraction.is_finite() { fraction.clamp(0.0, 1.0) } else { 0.0 };
    let filled = ((f * BAR as f64).floor() as usize).min(BAR);
    let bar: String = "#".repeat(filled) + &".".repeat(BAR - filled);
    let pct = (f * 100.0).floor() as u32;
    let left = if f >= 0.01 {
        let s = (elapsed.as_secs_f64() * (1.0 - f) / f).round() as u64;
        format!(", about {}:{:02} left", s / 60, s % 60)
    } else {
        String::new()
    };
    format!("{what} [{bar}] {pct:>3} %{left}")
}

/// What the bar last drew.
struct State {
    /// The step and when it started.
    step: Option<(String, Instant)>,
    last_draw: Option<Instant>,
    shown: bool,
}

/// The terminal's sink.
struct Bar {
    state: Mutex<State>,
}

impl ballbar_model::progress::Sink for Bar {
    fn update(&self, what: &str, done: usize, total: usize) {
        let Ok(mut st) = self.state.lock() else { return };
        let now = Instant::now();
        if st.step.as_ref().is_none_or(|(w, _)| w != what) {
            st.step = Some((what.to_string(), now));
            st.last_draw = None;
        }
        if st.last_draw.is_some_and(|t| now - t < REDRAW) {
            return;
        }
        let started = st.step.as_ref().map(|(_, t)| *t).unwrap_or(now);
        let line = render(what, done as f64 / total.max(1) as f64, now - started);
        st.last_draw = Some(now);
        st.shown = true;
        let mut err = std::io::stderr().lock();
        // `\r` to the line's start, the line, then erase what an earlier longer line left.
        let _ = write!(err, "\r{line}\x1b[K");
        let _ = err.flush();
    }

    fn finish(&self) {
        let Ok(mut st) = self.state.lock() else { return };
        if st.shown {
            let mut err = std::io::stderr().lock();
            let _ = write!(err, "\r\x1b[K");
            let _ = err.flush();
        }
        *st = State { step: None, last_draw: None, shown: false };
    }
}

/// Install the bar when `terminal` (standard error is a terminal); returns whether it was.
pub fn install(terminal: bool) -> bool {
    terminal
        && ballbar_model::progress::set_sink(Box::new(Bar {
            state: Mutex::new(State { step: None, last_draw: None, shown: false }),
        }))
}

/// Install the bar if standard error is a terminal.
pub fn install_for_stderr() -> bool {
    install(std::io::stderr().is_terminal())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_shows_the_fraction_and_the_time_left_at_the_rate_so_far() {
        // A quarter done in 30 s: three quarters left at that rate is 90 s.
        assert_eq!(
            render("fit", 0.25, Duration::from_secs(30)),
            "fit [#####...............]  25 %, about 1:30 left"
        );
        // Done: nothing left, the bar full.
        assert_eq!(
            render("fit", 1.0, Duration::from_secs(7)),
            "fit [####################] 100 %, about 0:00 left"
        );
        // Under a hundredth: no estimate yet; beyond the ends: clamped, never a panic.
        assert_eq!(render("x", 0.001, Duration::from_secs(5)), "x [....................]   0 %");
        assert_eq!(render("x", -3.0, Duration::ZERO), "x [....................]   0 %");
        assert_eq!(render("x", f64::NAN, Duration::ZERO), "x [....................]   0 %");
        // 2/3 done after 20 s: 10 s left (rounded), 66 % (floored, never 100 before the end).
        assert_eq!(
            render("d", 2.0 / 3.0, Duration::from_secs(20)),
            "d [#############.......]  66 %, about 0:10 left"
        );
    }

    #[test]
    fn nothing_is_installed_when_standard_error_is_not_a_terminal() {
        assert!(!install(false));
    }
}
