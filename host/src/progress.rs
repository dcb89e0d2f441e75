//! Progress of the host's long commands, in one place.
//!
//! - [`Progress`]: a count of cases (the walks of `sweep`, `beyond`, `pushes`, `speed`; the
//!   frames of a video). On a terminal (stderr) an `indicatif` bar with k/N, elapsed time and
//!   ETA, each finished case printed above it; otherwise plain lines, one per finished case:
//!   `[k/N] case-name: outcome (elapsed 1m02s, ETA 3m10s)`, never a `\r` rewrite. Safe to share
//!   between the workers of a parallel run: k counts finished cases under one lock.
//! - [`StatusLine`]: a live status (simulated time, bytes captured, the drive's state): rewritten
//!   in place on a terminal, a plain line at most every `every` otherwise.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How often a live status (simulated time, bytes captured, the drive's state) prints a plain
/// line when stderr is not a terminal.
pub const STATUS_EVERY: Duration = Duration::from_secs(10);

/// Where a plain-line reporter writes.
type Sink = Box<dyn Write + Send>;

/// Whether the standard error stream is a terminal (bars) or not (plain lines).
pub fn stderr_is_terminal() -> bool {
    std::io::stderr().is_terminal()
}

/// A duration for people: `45s`, `3m07s`, `1h02m`.
pub fn human(d: Duration) -> String {
    let s = d.as_secs();
    match s {
        0..=59 => format!("{s}s"),
        60..=3599 => format!("{}m{:02}s", s / 60, s % 60),
        _ => format!("{}h{:02}m", s / 3600, (s % 3600) / 60),
    }
}

/// The time left after `done` of `total` cases took `elapsed` (`None` before the first).
pub fn eta(elapsed: Duration, done: usize, total: usize) -> Option<Duration> {
    if done == 0 {
        return None;
    }
    let left = total.saturating_sub(done) as f64;
    Some(Duration::from_secs_f64(
        elapsed.as_secs_f64() / done as f64 * left,
    ))
}

struct State {
    done: usize,
    total: usize,
    running: Vec<String>,
    /// Plain-line mode: the writer; the next position (of [`Progress::position`]) that prints.
    sink: Option<Sink>,
    next_print: usize,
}

/// A count of cases with k/N and ETA (see the module docs).
pub struct Progress {
    bar: Option<ProgressBar>,
    state: Mutex<State>,
    start: Instant,
    verb: String,
}

impl Progress {
    /// On stderr: a bar on a terminal, plain lines otherwise; `verb` names what a running case
    /// does in the bar (`walking`, `rendering`).
    pub fn stderr(total: usize, verb: &str) -> Progress {
        if stderr_is_terminal() {
            Self::bar(total, verb, ProgressDrawTarget::stderr())
        } else {
            Self::lines(total, verb, Box::new(std::io::stderr()))
        }
    }

    /// Plain lines into `w` (what a pipe or a log file gets).
    pub fn lines(total: usize, verb: &str, w: Sink) -> Progress {
        Progress {
            bar: None,
            state: Mutex::new(State {
                done: 0,
                total,
                running: Vec::new(),
                sink: Some(w),
                next_print: 0,
            }),
            start: Instant::now(),
            verb: verb.to_string(),
        }
    }

    /// An `indicatif` bar drawn on `target`.
    fn bar(total: usize, verb: &str, target: ProgressDrawTarget) -> Progress {
        let bar = ProgressBar::with_draw_target(Some(total as u64), target);
        if let Ok(style) = ProgressStyle::with_template(
            "[{bar:30.cyan/blue}] {pos}/{len} {elapsed} elapsed, ETA {eta} {wide_msg}",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.enable_steady_tick(Duration::from_millis(500));
        Progress {
            bar: Some(bar),
            state: Mutex::new(State {
                done: 0,
                total,
                running: Vec::new(),
                sink: None,
                next_print: 0,
            }),
            start: Instant::now(),
            verb: verb.to_string(),
        }
    }

    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        // A worker that panicked while holding the lock left a consistent count behind.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn show_running(&self, st: &State) {
        if let Some(bar) = &self.bar {
            match st.running.is_empty() {
                true => bar.set_message(""),
                false => bar.set_message(format!("{} {}", self.verb, st.running.join(", "))),
            }
        }
    }

    /// Case `name` starts (shown in the bar; nothing in plain lines).
    pub fn start(&self, name: &str) {
        let mut st = self.state();
        st.running.push(name.to_string());
        self.show_running(&st);
    }

    /// Case `name` finished with `outcome`: k counts up and the line
    /// `[k/N] name: outcome (elapsed …, ETA …)` is printed.
    pub fn finish_case(&self, name: &str, outcome: &str) {
        let mut st = self.state();
        st.done += 1;
        st.total = st.total.max(st.done);
        if let Some(i) = st.running.iter().position(|r| r == name) {
            st.running.remove(i);
        }
        let elapsed = self.start.elapsed();
        let left = match eta(elapsed, st.done, st.total) {
            Some(d) if st.done < st.total => format!("ETA {}", human(d)),
            Some(_) => "done".to_string(),
            None => "ETA ?".to_string(),
        };
        let line = format!(
            "[{}/{}] {name}: {outcome} (elapsed {}, {left})",
            st.done,
            st.total,
            human(elapsed)
        );
        match &self.bar {
            Some(bar) => {
                bar.set_length(st.total as u64);
                bar.set_position(st.done as u64);
                bar.println(line);
            }
            None => {
                if let Some(w) = st.sink.as_mut() {
                    let _ = writeln!(w, "{line}");
                    let _ = w.flush();
                }
            }
        }
        self.show_running(&st);
    }

    /// The number of cases changed (a search that ended before its bound); never below the
    /// cases finished.
    pub fn set_total(&self, total: usize) {
        let mut st = self.state();
        st.total = total.max(st.done);
        if let Some(bar) = &self.bar {
            bar.set_length(st.total as u64);
        }
    }

    /// Cases finished and the current total (k, N).
    pub fn counts(&self) -> (usize, usize) {
        let st = self.state();
        (st.done, st.total)
    }

    /// Progress by position without per-case lines (the frames of a video): the bar moves to
    /// `k`; plain lines print `[k/N] label (elapsed …, ETA …)` at each tenth of N and at N.
    pub fn position(&self, k: usize, label: &str) {
        let mut st = self.state();
        st.done = k.min(st.total);
        if let Some(bar) = &self.bar {
            bar.set_position(st.done as u64);
            return;
        }
        let step = st.total.div_ceil(10).max(1);
        if st.next_print == 0 {
            st.next_print = step.min(st.total);
        }
        if st.done == 0 || st.done < st.next_print {
            return;
        }
        st.next_print = match st.done >= st.total {
            true => usize::MAX,
            false => ((st.done / step + 1) * step).min(st.total),
        };
        let elapsed = self.start.elapsed();
        let left = match eta(elapsed, st.done, st.total) {
            Some(d) if st.done < st.total => format!("ETA {}", human(d)),
            _ => "done".to_string(),
        };
        let line = format!(
            "[{}/{}] {label} (elapsed {}, {left})",
            st.done,
            st.total,
            human(elapsed)
        );
        if let Some(w) = st.sink.as_mut() {
            let _ = writeln!(w, "{line}");
            let _ = w.flush();
        }
    }

    /// The bar removed (the finished cases' lines stay); nothing in plain lines.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}

/// A live status line (see the module docs).
pub struct StatusLine {
    bar: Option<ProgressBar>,
    plain: Mutex<(Option<Sink>, Option<Instant>)>,
    every: Duration,
}

impl StatusLine {
    /// On stderr: rewritten in place on a terminal, else a plain line at most every `every`.
    pub fn stderr(every: Duration) -> StatusLine {
        if stderr_is_terminal() {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            if let Ok(style) = ProgressStyle::with_template("{wide_msg}") {
                bar.set_style(style);
            }
            StatusLine {
                bar: Some(bar),
                plain: Mutex::new((None, None)),
                every,
            }
        } else {
            Self::lines(Box::new(std::io::stderr()), every)
        }
    }

    /// Plain lines into `w`, at most every `every` (the first at once).
    pub fn lines(w: Sink, every: Duration) -> StatusLine {
        StatusLine {
            bar: None,
            plain: Mutex::new((Some(w), None)),
            every,
        }
    }

    /// The status is now `line`.
    pub fn set(&self, line: &str) {
        if let Some(bar) = &self.bar {
            bar.set_message(line.to_string());
            return;
        }
        let mut p = self.plain.lock().unwrap_or_else(|e| e.into_inner());
        if p.1.is_some_and(|t| t.elapsed() < self.every) {
            return;
        }
        p.1 = Some(Instant::now());
        if let Some(w) = p.0.as_mut() {
            let _ = writeln!(w, "{line}");
            let _ = w.flush();
        }
    }

    /// Ends the line: on a terminal the last status stays on screen.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.abandon();
        }
    }
}

impl Drop for StatusLine {
    fn drop(&mut self) {
        self.finish();
    }
}

/// A writer into a shared buffer (tests: what a pipe would receive).
#[derive(Clone, Default)]
pub struct SharedBuffer(std::sync::Arc<Mutex<Vec<u8>>>);

impl SharedBuffer {
    /// The bytes written so far, as text.
    pub fn text(&self) -> String {
        let b = self.0.lock().unwrap_or_else(|e| e.into_inner());
        String::from_utf8_lossy(&b).into_owned()
    }
}

impl Write for SharedBuffer {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let mut b = self.0.lock().unwrap_or_else(|e| e.into_inner());
        b.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_eta_read_like_people_write_them() {
        assert_eq!(human(Duration::from_secs(45)), "45s");
        assert_eq!(human(Duration::from_secs(187)), "3m07s");
        assert_eq!(human(Duration::from_secs(3720)), "1h02m");
        assert_eq!(eta(Duration::from_secs(60), 0, 4), None);
        assert_eq!(
            eta(Duration::from_secs(60), 2, 4),
            Some(Duration::from_secs(60))
        );
        assert_eq!(eta(Duration::from_secs(60), 4, 4), Some(Duration::ZERO));
    }

    /// Plain lines: one per finished case with k/N, no `\r`; a shrinking total (a search that
    /// ended early) shows in the next line.
    #[test]
    fn plain_lines_count_the_finished_cases() {
        let buf = SharedBuffer::default();
        let p = Progress::lines(3, "walking", Box::new(buf.clone()));
        p.start("a");
        p.start("b");
        p.finish_case("b", "fell");
        p.finish_case("a", "survived");
        p.set_total(2);
        p.finish();
        let text = buf.text();
        assert!(!text.contains('\r'), "{text:?}");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(lines[0].starts_with("[1/3] b: fell (elapsed "), "{text}");
        assert!(lines[0].contains("ETA "), "{text}");
        assert!(
            lines[1].starts_with("[2/3] a: survived (elapsed "),
            "{text}"
        );
        assert_eq!(p.counts(), (2, 2));
    }

    /// Frames: a line at each tenth, not one per frame.
    #[test]
    fn positions_print_at_each_tenth() {
        let buf = SharedBuffer::default();
        let p = Progress::lines(200, "rendering", Box::new(buf.clone()));
        for k in 1..=200 {
            p.position(k, "frames");
        }
        p.position(200, "frames");
        let text = buf.text();
        assert_eq!(text.lines().count(), 10, "{text}");
        assert!(text
            .lines()
            .next()
            .is_some_and(|l| l.starts_with("[20/200] frames")));
        assert!(text
            .lines()
            .last()
            .is_some_and(|l| l.starts_with("[200/200] frames")));
        assert!(text.lines().last().is_some_and(|l| l.ends_with("done)")));
    }

    #[test]
    fn a_plain_status_line_is_throttled() {
        let buf = SharedBuffer::default();
        let s = StatusLine::lines(Box::new(buf.clone()), Duration::from_secs(3600));
        s.set("one");
        s.set("two");
        s.finish();
        assert_eq!(buf.text(), "one\n");
    }
}
