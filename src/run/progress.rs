//! What `train` shows while it runs: on a terminal, a progress bar that fills toward the run's
//! stop rule (the active-time budget or the iteration budget, whichever comes first; success
//! may stop it earlier) with an estimate of the time left, frames/s, return, episode length
//! and the last success rate; otherwise (scripts, the HPO search, a log file) one line per
//! evaluation, with the same budget and estimate, and nothing in between.

use std::io::{IsTerminal, Write};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::config::RunConfig;
use super::metrics::IterationRecord;

/// How progress is shown.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressMode {
    /// A progress bar on stdout.
    Bar,
    /// One line per evaluation.
    Lines,
    /// Nothing.
    Quiet,
}

impl ProgressMode {
    /// A bar when stdout is a terminal, lines otherwise.
    pub fn for_stdout() -> ProgressMode {
        if std::io::stdout().is_terminal() {
            ProgressMode::Bar
        } else {
            ProgressMode::Lines
        }
    }
}

/// The bar's length: progress toward the budget in thousandths.
const BAR_STEPS: u64 = 1000;

/// How far a run is toward its stop rule, and when it will get there at the pace so far.
#[derive(Clone, Debug, PartialEq)]
pub struct Budget {
    time_budget_s: f64,
    max_iterations: u64,
    /// The success rate that stops the run early (`run.stop_on_success`), if one does.
    stop_at_success: Option<f64>,
    /// Where the pace is measured from: iteration, active seconds (the first iteration this
    /// process recorded, so that start-up is not in the pace).
    start_iteration: u64,
    start_active_s: f64,
}

impl Budget {
    pub fn new(run: &RunConfig, start_iteration: u64, start_active_s: f64) -> Budget {
        Budget {
            time_budget_s: run.time_budget_s,
            max_iterations: run.max_iterations,
            stop_at_success: run.stop_on_success.then_some(run.success_rate),
            start_iteration,
            start_active_s,
        }
    }

    /// The fraction (0 to 1) of the budget that binds first, spent after `record`.
    pub fn fraction(&self, record: &IterationRecord) -> f64 {
        let time = record.active_time_s / self.time_budget_s;
        let iterations = record.iteration as f64 / self.max_iterations as f64;
        time.max(iterations).clamp(0.0, 1.0)
    }

    /// Wall seconds until a budget is spent, at the pace so far (`wall_s` seconds since the
    /// start point, evaluations and checkpoints included); `None` before there is a pace.
    pub fn eta_s(&self, record: &IterationRecord, wall_s: f64) -> Option<f64> {
        let active = record.active_time_s - self.start_active_s;
        let iterations = record.iteration.saturating_sub(self.start_iteration);
        if active <= 0.0 || iterations == 0 || wall_s <= 0.0 {
            return None;
        }
        let by_time = (self.time_budget_s - record.active_time_s).max(0.0) * wall_s / active;
        let by_iterations = self.max_iterations.saturating_sub(record.iteration) as f64 * wall_s
            / iterations as f64;
        Some(by_time.min(by_iterations))
    }

    /// "12.3/60 s active, ETA 48 s (or success 0.900)": the binding budget, spent and whole,
    /// and the estimate.
    pub fn status(&self, record: &IterationRecord, wall_s: f64) -> String {
        let time = record.active_time_s / self.time_budget_s;
        let iterations = record.iteration as f64 / self.max_iterations as f64;
        let spent = if time >= iterations {
            format!(
                "{:.1}/{} s active",
                record.active_time_s,
                short_number(self.time_budget_s)
            )
        } else {
            format!("it {}/{}", record.iteration, self.max_iterations)
        };
        let eta = self
            .eta_s(record, wall_s)
            .map_or("-".to_string(), short_duration);
        match self.stop_at_success {
            Some(rate) => format!("{spent}, ETA {eta} (or success {rate:.3})"),
            None => format!("{spent}, ETA {eta}"),
        }
    }
}

/// `60`, `12.5`: a budget as given.
fn short_number(value: f64) -> String {
    if value.fract() == 0.0 && value.abs() < 1e15 {
        format!("{value:.0}")
    } else {
        format!("{value}")
    }
}

/// `48 s`, `3 min 20 s`, `2 h 05 min`.
fn short_duration(seconds: f64) -> String {
    let s = seconds.round().max(0.0) as u64;
    if s < 60 {
        format!("{s} s")
    } else if s < 3600 {
        format!("{} min {:02} s", s / 60, s % 60)
    } else {
        format!("{} h {:02} min", s / 3600, (s % 3600) / 60)
    }
}

/// The progress display of one run.
pub struct Progress {
    bar: Option<ProgressBar>,
    lines: Option<Box<dyn Write + Send>>,
    last_success_rate: Option<f64>,
    budget: Budget,
    /// When the first iteration was recorded (the pace's start point).
    first_record: Option<Instant>,
}

impl Progress {
    /// A display for a run with `run`'s stop rule.
    pub fn new(mode: ProgressMode, run: &RunConfig) -> Progress {
        let budget = Budget::new(run, 0, 0.0);
        match mode {
            ProgressMode::Bar => {
                let bar =
                    ProgressBar::with_draw_target(Some(BAR_STEPS), ProgressDrawTarget::stdout());
                // The template is a constant: it parses.
                if let Ok(style) = ProgressStyle::with_template("{bar:30} {msg}  [{elapsed}]") {
                    bar.set_style(style);
                }
                Progress {
                    bar: Some(bar),
                    lines: None,
                    last_success_rate: None,
                    budget,
                    first_record: None,
                }
            }
            ProgressMode::Lines => Progress::lines_to(Box::new(std::io::stdout()), budget),
            ProgressMode::Quiet => Progress {
                bar: None,
                lines: None,
                last_success_rate: None,
                budget,
                first_record: None,
            },
        }
    }

    /// Line mode into any writer (tests, logs).
    pub fn lines_to(out: Box<dyn Write + Send>, budget: Budget) -> Progress {
        Progress {
            bar: None,
            lines: Some(out),
            last_success_rate: None,
            budget,
            first_record: None,
        }
    }

    /// Shows an iteration's record; an evaluation also prints a line in line mode.
    pub fn iteration(&mut self, record: &IterationRecord) {
        if let Some(e) = &record.evaluation {
            self.last_success_rate = Some(e.success_rate);
        }
        let since_first = match self.first_record {
            Some(at) => at.elapsed().as_secs_f64(),
            None => {
                self.first_record = Some(Instant::now());
                self.budget.start_iteration = record.iteration;
                self.budget.start_active_s = record.active_time_s;
                0.0
            }
        };
        let status = self.budget.status(record, since_first);
        // A task's own evaluation (the goal task's, docs/goal.md) has a line of its own.
        let goal_line = record
            .task
            .as_ref()
            .and_then(|t| t.progress_line(record.iteration, record.active_time_s));
        if let Some(bar) = &self.bar {
            bar.set_position((self.budget.fraction(record) * BAR_STEPS as f64) as u64);
            bar.set_message(format!(
                "{status}  {}",
                bar_message(record, self.last_success_rate)
            ));
            if record.evaluation.is_some() {
                bar.println(evaluation_line(record));
            }
            if let Some(line) = &goal_line {
                bar.println(line);
            }
        } else if let Some(out) = &mut self.lines {
            // Progress output is best effort: a closed pipe must not stop training.
            if record.evaluation.is_some() {
                let _ = writeln!(out, "{}  [{status}]", evaluation_line(record));
            }
            if let Some(line) = &goal_line {
                let _ = writeln!(out, "{line}");
            }
            let _ = out.flush();
        }
    }

    /// A message (a warning, a checkpoint) above the bar, or as a line.
    pub fn note(&mut self, message: &str) {
        if let Some(bar) = &self.bar {
            bar.println(message);
        } else if let Some(out) = &mut self.lines {
            let _ = writeln!(out, "{message}");
            let _ = out.flush();
        }
    }

    /// Leaves the bar as it is (its last state stays on screen).
    pub fn finish(&mut self) {
        if let Some(bar) = &self.bar {
            bar.abandon();
        }
    }
}

/// The bar's message: frames/s, return, episode length, last success rate.
pub fn bar_message(record: &IterationRecord, last_success_rate: Option<f64>) -> String {
    let success = last_success_rate.map_or("-".to_string(), |s| format!("{s:.3}"));
    format!(
        "{:.3} M frames/s  return {:.2}  episode {:.1}  success {success}  {:.2} s active",
        record.frames_per_s / 1e6,
        record.mean_return,
        record.mean_episode_length,
        record.active_time_s
    )
}

/// The line of an evaluation iteration.
pub fn evaluation_line(record: &IterationRecord) -> String {
    let mut line = format!(
        "iteration {:>5}  {:>8.2} s active  {:.3} M frames/s  return {:.2}  episode {:.1}",
        record.iteration,
        record.active_time_s,
        record.frames_per_s / 1e6,
        record.mean_return,
        record.mean_episode_length
    );
    if let Some(e) = &record.evaluation {
        match e.stopped_at_step {
            // The episodes still running count as failed: the rates are lower bounds.
            Some(step) => line.push_str(&format!(
                "  success >={:.3} ({}/{}), stopped at step {step} of {}: out of reach",
                e.success_rate, e.completed, e.episodes, e.episode_steps
            )),
            None => line.push_str(&format!(
                "  success {:.3} ({}/{}){}  pose error {:.4} m",
                e.success_rate,
                e.completed,
                e.episodes,
                if e.success { " reached" } else { "" },
                e.pose_error_m
            )),
        }
        if let Some(library) = &e.library {
            line.push_str(&format!(
                "  clips at {} {}/{}",
                super::library_scores::CLIP_SUCCESS_RATE,
                library.clips_at_threshold,
                library.clips.len()
            ));
        }
    }
    line
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use super::*;
    use crate::run::evaluation::EvaluationSummary;
    use crate::run::metrics::UpdateStats;

    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0
                .lock()
                .map_err(|_| std::io::Error::other("poisoned"))?
                .extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn record(iteration: u64, evaluated: bool) -> IterationRecord {
        IterationRecord {
            iteration,
            active_time_s: 0.5 * iteration as f64,
            frames: 131_072 * iteration,
            frames_per_s: 612_345.0,
            mean_return: 12.345,
            mean_episode_length: 45.67,
            update: UpdateStats::default(),
            termination: Default::default(),
            evaluation: evaluated.then(|| EvaluationSummary {
                episodes: 32,
                completed: 29,
                succeeded: 29,
                success_rate: 29.0 / 32.0,
                success: true,
                clip_start_success: true,
                robotics_rule_passed: 0,
                robotics_rule_rate: 0.0,
                clip_start_robotics_rule: false,
                clip_start_completed: false,
                episode_steps: 53,
                mean_episode_steps: 51.0,
                pose_error_m: 0.04321,
                global_mpjpe_m: 0.1,
                ee_position_error_m: 0.1,
                ee_orientation_error_rad: 0.1,
                library: None,
                stopped_at_step: None,
            }),
            divergence: None,
            task: None,
            wall_s: None,
        }
    }

    #[test]
    fn line_mode_prints_one_line_per_evaluation() {
        let out = Shared::default();
        let run = RunConfig {
            time_budget_s: 10.0,
            ..RunConfig::default()
        };
        let mut progress = Progress::lines_to(Box::new(out.clone()), Budget::new(&run, 0, 0.0));
        for i in 1..=10 {
            progress.iteration(&record(i, i % 5 == 0));
        }
        progress.note("checkpoint written");
        progress.finish();
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        let (line, status) = lines[0].split_once("  [").unwrap();
        assert_eq!(
            line,
            "iteration     5      2.50 s active  0.612 M frames/s  return 12.35  episode 45.7  success 0.906 (29/32) reached  pose error 0.0432 m"
        );
        // The time budget binds (2.5 of 10 s, against 5 of 5000 iterations).
        assert!(status.starts_with("2.5/10 s active, ETA "), "{status}");
        assert!(status.ends_with(" (or success 0.900)]"), "{status}");
        assert!(lines[1].starts_with("iteration    10"), "{text}");
        assert!(lines[1].contains("5.0/10 s active, ETA "), "{text}");
        assert_eq!(lines[2], "checkpoint written");
    }

    #[test]
    fn the_budget_counts_toward_whichever_limit_comes_first() {
        let run = RunConfig {
            time_budget_s: 60.0,
            max_iterations: 40,
            stop_on_success: false,
            ..RunConfig::default()
        };
        let budget = Budget::new(&run, 0, 0.0);
        // Iteration 10 at 5 s: a quarter of the iterations, a twelfth of the time.
        let r = record(10, false);
        assert_eq!(budget.fraction(&r), 0.25);
        // 20 s of wall time for 10 iterations: 30 iterations left take 60 s; the time budget
        // (55 active s at 4 wall s per active s) would take longer.
        assert_eq!(budget.eta_s(&r, 20.0), Some(60.0));
        assert_eq!(budget.status(&r, 20.0), "it 10/40, ETA 1 min 00 s");
        assert_eq!(budget.eta_s(&r, 0.0), None);
        // A resumed run measures its pace from where it resumed.
        let resumed = Budget::new(&run, 10, 5.0);
        assert_eq!(resumed.eta_s(&r, 3.0), None);
        assert_eq!(resumed.eta_s(&record(20, false), 10.0), Some(20.0));
        // Past the budget: full, nothing left.
        assert_eq!(budget.fraction(&record(400, false)), 1.0);
        assert_eq!(budget.eta_s(&record(400, false), 10.0), Some(0.0));
        assert_eq!(short_duration(7384.0), "2 h 03 min");
    }

    #[test]
    fn the_bar_message_carries_the_last_success_rate() {
        assert_eq!(
            bar_message(&record(3, false), None),
            "0.612 M frames/s  return 12.35  episode 45.7  success -  1.50 s active"
        );
        assert!(bar_message(&record(3, false), Some(0.5)).contains("success 0.500"));
    }

    #[test]
    fn an_evaluation_stopped_when_out_of_reach_says_so() {
        let mut r = record(10, true);
        if let Some(e) = r.evaluation.as_mut() {
            e.success = false;
            e.completed = 3;
            e.success_rate = 3.0 / 32.0;
            e.stopped_at_step = Some(12);
        }
        let line = evaluation_line(&r);
        assert!(
            line.contains("success >=0.094 (3/32), stopped at step 12 of 53: out of reach"),
            "{line}"
        );
        assert!(
            !line.contains("pose error"),
            "a partial pose error is not shown: {line}"
        );
    }
}
