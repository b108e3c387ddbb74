//! What `train` shows while it runs: on a terminal, a progress bar (iteration, frames/s,
//! return, episode length, last success rate); otherwise (scripts, the HPO search, a log file)
//! one line per evaluation and nothing in between.

use std::io::{IsTerminal, Write};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

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

/// The progress display of one run.
pub struct Progress {
    bar: Option<ProgressBar>,
    lines: Option<Box<dyn Write + Send>>,
    last_success_rate: Option<f64>,
}

impl Progress {
    /// A display for a run that ends by `max_iterations` and has done `start_iteration`.
    pub fn new(mode: ProgressMode, start_iteration: u64, max_iterations: u64) -> Progress {
        match mode {
            ProgressMode::Bar => {
                let bar = ProgressBar::with_draw_target(
                    Some(max_iterations),
                    ProgressDrawTarget::stdout(),
                );
                // The template is a constant: it parses.
                if let Ok(style) =
                    ProgressStyle::with_template("{bar:30} {pos}/{len} it  {msg}  [{elapsed}]")
                {
                    bar.set_style(style);
                }
                bar.set_position(start_iteration);
                Progress {
                    bar: Some(bar),
                    lines: None,
                    last_success_rate: None,
                }
            }
            ProgressMode::Lines => Progress::lines_to(Box::new(std::io::stdout())),
            ProgressMode::Quiet => Progress {
                bar: None,
                lines: None,
                last_success_rate: None,
            },
        }
    }

    /// Line mode into any writer (tests, logs).
    pub fn lines_to(out: Box<dyn Write + Send>) -> Progress {
        Progress {
            bar: None,
            lines: Some(out),
            last_success_rate: None,
        }
    }

    /// Shows an iteration's record; an evaluation also prints a line in line mode.
    pub fn iteration(&mut self, record: &IterationRecord) {
        if let Some(e) = &record.evaluation {
            self.last_success_rate = Some(e.success_rate);
        }
        // The goal task's evaluation (docs/goal.md) has a line of its own.
        let goal_line = super::goal::goal_progress_line(record);
        if let Some(bar) = &self.bar {
            bar.set_position(record.iteration);
            bar.set_message(bar_message(record, self.last_success_rate));
            if record.evaluation.is_some() {
                bar.println(evaluation_line(record));
            }
            if let Some(line) = &goal_line {
                bar.println(line);
            }
        } else if let Some(out) = &mut self.lines {
            // Progress output is best effort: a closed pipe must not stop training.
            if record.evaluation.is_some() {
                let _ = writeln!(out, "{}", evaluation_line(record));
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
        line.push_str(&format!(
            "  success {:.3} ({}/{}){}  pose error {:.4} m",
            e.success_rate,
            e.completed,
            e.episodes,
            if e.success { " reached" } else { "" },
            e.pose_error_m
        ));
        if let Some(library) = &e.library {
            line.push_str(&format!(
                "  clips at {} {}/{}",
                super::library_evaluation::CLIP_SUCCESS_RATE,
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
    use crate::train::evaluation::EvaluationSummary;
    use crate::train::metrics::UpdateStats;

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
                episode_steps: 53,
                mean_episode_steps: 51.0,
                pose_error_m: 0.04321,
                global_mpjpe_m: 0.1,
                ee_position_error_m: 0.1,
                ee_orientation_error_rad: 0.1,
                library: None,
            }),
            divergence: None,
            goal: None,
        }
    }

    #[test]
    fn line_mode_prints_one_line_per_evaluation() {
        let out = Shared::default();
        let mut progress = Progress::lines_to(Box::new(out.clone()));
        for i in 1..=10 {
            progress.iteration(&record(i, i % 5 == 0));
        }
        progress.note("checkpoint written");
        progress.finish();
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        assert_eq!(
            lines[0],
            "iteration     5      2.50 s active  0.612 M frames/s  return 12.35  episode 45.7  success 0.906 (29/32) reached  pose error 0.0432 m"
        );
        assert!(lines[1].starts_with("iteration    10"), "{text}");
        assert_eq!(lines[2], "checkpoint written");
    }

    #[test]
    fn the_bar_message_carries_the_last_success_rate() {
        assert_eq!(
            bar_message(&record(3, false), None),
            "0.612 M frames/s  return 12.35  episode 45.7  success -  1.50 s active"
        );
        assert!(bar_message(&record(3, false), Some(0.5)).contains("success 0.500"));
    }
}
