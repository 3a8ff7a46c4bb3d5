//! Progress of long runs (training, evaluation, collection) on stderr: an indicatif bar when
//! stderr is a terminal; otherwise (a log file, CI) a plain line at most every
//! [`PLAIN_LINE_SECONDS`] and at the end, e.g.
//! `teacher: step 1200/15000 (8 %) loss 0.01234 lr 9.8e-4, elapsed 0:42, eta 8:03`.
use indicatif::{ProgressBar, ProgressStyle};
use std::time::{Duration, Instant};

/// Seconds between two plain progress lines.
pub const PLAIN_LINE_SECONDS: u64 = 30;

/// One long run's progress.
pub struct Progress {
    bar: ProgressBar,
    label: String,
    /// What is counted, e.g. `step`.
    unit: &'static str,
    total: u64,
    start: Instant,
    /// When the last plain line was printed (`None`: none yet).
    last_line: Option<Instant>,
}

impl Progress {
    /// Progress over `total` units (`unit`: `step`, `episode`) labelled `label`.
    pub fn new(label: &str, total: u64, unit: &'static str) -> Self {
        let bar = ProgressBar::new(total);
        let template = format!("{{prefix}} [{{elapsed_precise}}] {{bar:30}} {{pos}}/{{len}} {unit}s {{msg}} (eta {{eta}})");
        bar.set_style(
            ProgressStyle::with_template(&template)
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_prefix(label.to_string());
        Progress {
            bar,
            label: label.to_string(),
            unit,
            total,
            start: Instant::now(),
            last_line: None,
        }
    }

    /// Reports `position` units done with a short status `message` (e.g. the loss).
    pub fn update(&mut self, position: u64, message: &str) {
        if !self.bar.is_hidden() {
            self.bar.set_position(position);
            self.bar.set_message(message.to_string());
            return;
        }
        let now = Instant::now();
        let due = self
            .last_line
            .is_none_or(|t| now.duration_since(t) >= Duration::from_secs(PLAIN_LINE_SECONDS));
        if due || position >= self.total {
            self.last_line = Some(now);
            eprintln!(
                "{}",
                self.plain_line(position, message, now.duration_since(self.start))
            );
        }
    }

    /// The plain progress line after `elapsed`.
    fn plain_line(&self, position: u64, message: &str, elapsed: Duration) -> String {
        let percent = 100 * position / self.total.max(1);
        let eta = match position {
            0 => "-".to_string(),
            done => clock(elapsed.mul_f64(self.total.saturating_sub(done) as f64 / done as f64)),
        };
        let message = if message.is_empty() {
            String::new()
        } else {
            format!(" {message}")
        };
        format!(
            "{}: {} {position}/{} ({percent} %){message}, elapsed {}, eta {eta}",
            self.label,
            self.unit,
            self.total,
            clock(elapsed)
        )
    }

    /// Prints a line without disturbing the bar.
    pub fn println(&self, line: &str) {
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }

    /// Removes the bar (plain output stays as it is).
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// `m:ss`, or `h:mm:ss` from an hour on.
fn clock(duration: Duration) -> String {
    let s = duration.as_secs();
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_lines_show_position_status_elapsed_and_eta() {
        let p = Progress::new("teacher", 15000, "step");
        let line = p.plain_line(1200, "loss 0.01234 lr 9.8e-4", Duration::from_secs(42));
        assert_eq!(
            line,
            "teacher: step 1200/15000 (8 %) loss 0.01234 lr 9.8e-4, elapsed 0:42, eta 8:03"
        );
        assert_eq!(
            p.plain_line(0, "", Duration::ZERO),
            "teacher: step 0/15000 (0 %), elapsed 0:00, eta -"
        );
        assert_eq!(clock(Duration::from_secs(3 * 3600 + 61)), "3:01:01");
    }
}
