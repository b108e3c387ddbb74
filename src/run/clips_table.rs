//! A motion library's per-clip tables: `clips.tsv` of a run (with the active time at which each
//! clip first reached [`CLIP_SUCCESS_RATE`]) and `eval --out`'s.

use std::fmt::Write as _;

use super::evaluation::EvaluationSummary;
use super::library_scores::{CLIP_SUCCESS_RATE, ClipScore, LibraryEvaluation};
use super::metrics::IterationRecord;

/// The columns of a per-clip table that every library evaluation has (`clips.tsv` adds the
/// active time at which each reached [`CLIP_SUCCESS_RATE`]; `eval --out` writes these alone).
pub(crate) const CLIP_TABLE_COLUMNS: &str = "clip\tduration_s\tloop\tevaluated_over\tepisode_steps\tepisodes\tsucceeded\tsuccess_rate\tglobal_mpjpe_m\tpose_error_m";

/// A table's number: 4 decimals, `-` when not finite (no step was scored).
fn table_number(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.4}")
    } else {
        "-".to_string()
    }
}

/// Clip `c`'s row of [`CLIP_TABLE_COLUMNS`].
pub(crate) fn clip_table_row(c: &ClipScore) -> String {
    let over = c
        .window_s
        .map_or("whole clip".to_string(), |w| format!("{w} s windows"));
    format!(
        "{}\t{:.3}\t{}\t{over}\t{}\t{}\t{}\t{:.3}\t{}\t{}",
        c.name,
        c.duration_s,
        c.loop_mode,
        c.episode_steps,
        c.episodes,
        c.succeeded,
        c.success_rate,
        table_number(c.global_mpjpe_m),
        table_number(c.pose_error_m),
    )
}

/// The whole library's row of [`CLIP_TABLE_COLUMNS`] for evaluation `summary` (its episodes,
/// and how many clips reached [`CLIP_SUCCESS_RATE`] in the first column).
pub(crate) fn library_table_row(
    library: &LibraryEvaluation,
    summary: &EvaluationSummary,
) -> String {
    format!(
        "all ({} of {} clips at {CLIP_SUCCESS_RATE})\t{:.3}\t-\t-\t{}\t{}\t{}\t{:.3}\t{}\t{}",
        library.clips_at_threshold,
        library.clips.len(),
        library.clips.iter().map(|c| c.duration_s).sum::<f64>(),
        summary.episode_steps,
        summary.episodes,
        summary.succeeded,
        summary.success_rate,
        table_number(summary.global_mpjpe_m),
        table_number(summary.pose_error_m),
    )
}

/// `clips.tsv`: the latest evaluation's per-clip table, with the active time at which each
/// clip first reached [`CLIP_SUCCESS_RATE`], and a last row for the whole library (the run's
/// time to success: episodes and every clip). None before a library evaluation.
pub fn clips_table(records: &[IterationRecord]) -> Option<String> {
    let evaluated = || {
        records.iter().filter_map(|r| {
            let e = r.evaluation.as_ref()?;
            Some((r.active_time_s, e, e.library.as_ref()?))
        })
    };
    let (_, last, library) = evaluated().next_back()?;
    let first_at = |name: &str| {
        evaluated().find_map(|(t, _, l)| {
            l.clips
                .iter()
                .any(|c| c.name == name && c.success_rate >= CLIP_SUCCESS_RATE)
                .then_some(t)
        })
    };
    let time = |t: Option<f64>| t.map_or("-".to_string(), |t| format!("{t:.3}"));
    let rate = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.3}"));
    let mut out = format!(
        "{CLIP_TABLE_COLUMNS}\ttime_to_threshold_s\treset_share\tframe_share\tfailures_per_step\n"
    );
    for c in &library.clips {
        let _ = writeln!(
            out,
            "{}\t{}\t{}\t{}\t{}",
            clip_table_row(c),
            time(first_at(&c.name)),
            rate(c.reset_share),
            rate(c.frame_share),
            rate(c.failures_per_step)
        );
    }
    let run_success = evaluated().find_map(|(t, e, _)| e.success.then_some(t));
    let _ = writeln!(
        out,
        "{}\t{}\t-\t-\t-",
        library_table_row(library, last),
        time(run_success)
    );
    Some(out)
}
