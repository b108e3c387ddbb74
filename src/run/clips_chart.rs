//! `clips.png`: a motion library run's per-clip success over active training time, one row
//! per clip and one column per evaluation, colored from red (0) through yellow to green (1),
//! with a dot on every cell at `CLIP_SUCCESS_RATE` or above. Where `clips.tsv` gives the
//! latest numbers, this shows at a glance which clips never learn, which learn late and which
//! come and go. Drawn with the embedded font as `curve.rs`.

use plotters::prelude::*;

use super::error::RunError;
use super::library_scores::CLIP_SUCCESS_RATE;
use super::metrics::IterationRecord;

pub const CHART_WIDTH: u32 = 1000;
/// Pixels per clip row (the chart's height follows the clip count).
const ROW_HEIGHT: u32 = 26;
const MARGINS_HEIGHT: u32 = 130;

fn plot_error(e: impl std::fmt::Display) -> RunError {
    RunError::Plot(e.to_string())
}

/// The color of a success rate: red at 0, yellow at 0.5, green at 1 (clamped; NaN grey).
pub fn success_color(rate: f64) -> RGBColor {
    if !rate.is_finite() {
        return RGBColor(190, 190, 190);
    }
    let r = rate.clamp(0.0, 1.0);
    let mix =
        |a: u8, b: u8, t: f64| (f64::from(a) + (f64::from(b) - f64::from(a)) * t).round() as u8;
    let (red, yellow, green) = ((200, 45, 40), (235, 200, 60), (40, 155, 70));
    let (from, to, t) = if r < 0.5 {
        (red, yellow, r * 2.0)
    } else {
        (yellow, green, (r - 0.5) * 2.0)
    };
    RGBColor(
        mix(from.0, to.0, t),
        mix(from.1, to.1, t),
        mix(from.2, to.2, t),
    )
}

/// The chart's height for `clips` rows.
pub fn chart_height(clips: usize) -> u32 {
    MARGINS_HEIGHT + ROW_HEIGHT * clips.max(1) as u32
}

/// Per-clip success over time as PNG bytes, or None when no record holds a library's
/// evaluation (a single clip or a goal run: `curve.png` says it all). The clips are the last
/// evaluation's, in the library's order.
pub fn clips_chart_png(
    records: &[IterationRecord],
    title: &str,
) -> Option<Result<Vec<u8>, RunError>> {
    let evaluations: Vec<(f64, &super::library_scores::LibraryEvaluation)> = records
        .iter()
        .filter_map(|r| Some((r.active_time_s, r.evaluation.as_ref()?.library.as_ref()?)))
        .filter(|(t, _)| t.is_finite())
        .collect();
    let (_, last) = evaluations.last()?;
    let names: Vec<String> = last.clips.iter().map(|c| c.name.clone()).collect();
    let rows = names.len();
    let t_hi = evaluations.last().map_or(1.0, |e| e.0).max(1e-3) * 1.01;
    Some(crate::plot::render_png(
        CHART_WIDTH,
        chart_height(rows),
        plot_error,
        |root| {
            let mut chart = ChartBuilder::on(root)
                .caption(title, ("sans-serif", 22))
                .margin(14)
                .x_label_area_size(44)
                .y_label_area_size(170)
                .build_cartesian_2d(0f64..t_hi, 0f64..rows as f64)
                .map_err(plot_error)?;
            let label = |y: &f64| {
                // Row i (from the top) spans [rows - i - 1, rows - i); its label sits at the middle.
                let from_top = rows as f64 - y - 0.5;
                let i = from_top.round();
                if (from_top - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < rows {
                    names[i as usize].clone()
                } else {
                    String::new()
                }
            };
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc(format!(
                    "active training time (s); a dot: the clip at {CLIP_SUCCESS_RATE} or above"
                ))
                .y_labels(rows * 2 + 1)
                .y_label_formatter(&label)
                .label_style(("sans-serif", 14))
                .axis_desc_style(("sans-serif", 16))
                .draw()
                .map_err(plot_error)?;
            let mut start = 0.0;
            for &(t, library) in &evaluations {
                for (i, name) in names.iter().enumerate() {
                    let Some(clip) = library.clips.iter().find(|c| &c.name == name) else {
                        continue;
                    };
                    let y = (rows - i - 1) as f64;
                    let color = success_color(clip.success_rate);
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [(start, y), (t, y + 1.0)],
                            color.filled(),
                        )))
                        .map_err(plot_error)?;
                    if clip.success_rate >= CLIP_SUCCESS_RATE {
                        chart
                            .draw_series(std::iter::once(Circle::new(
                                ((start + t) / 2.0, y + 0.5),
                                2,
                                BLACK.filled(),
                            )))
                            .map_err(plot_error)?;
                    }
                }
                start = t;
            }
            Ok(())
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::evaluation::EvaluationSummary;
    use crate::run::library_scores::{ClipScore, LibraryEvaluation};

    fn clip(name: &str, success_rate: f64) -> ClipScore {
        ClipScore {
            name: name.to_owned(),
            duration_s: 1.0,
            loop_mode: "wrap".to_owned(),
            window_s: None,
            episode_steps: 30,
            episodes: 10,
            succeeded: (success_rate * 10.0) as u32,
            success_rate,
            global_mpjpe_m: 0.1,
            pose_error_m: 0.05,
            reset_share: None,
            frame_share: None,
            failures_per_step: None,
        }
    }

    fn record(i: u64, library: Option<LibraryEvaluation>) -> IterationRecord {
        let evaluation = EvaluationSummary {
            episodes: 20,
            completed: 10,
            succeeded: 10,
            success_rate: 0.5,
            success: false,
            clip_start_success: false,
            robotics_rule_passed: 0,
            robotics_rule_rate: 0.0,
            clip_start_robotics_rule: false,
            clip_start_completed: false,
            episode_steps: 30,
            mean_episode_steps: 20.0,
            pose_error_m: 0.05,
            global_mpjpe_m: 0.1,
            ee_position_error_m: 0.05,
            ee_orientation_error_rad: 0.1,
            library,
            stopped_at_step: None,
        };
        IterationRecord {
            iteration: i,
            active_time_s: i as f64,
            frames: 100 * i,
            frames_per_s: 100.0,
            mean_return: 1.0,
            mean_episode_length: 10.0,
            update: Default::default(),
            termination: Default::default(),
            evaluation: Some(evaluation),
            divergence: None,
            task: None,
            wall_s: None,
        }
    }

    fn library(walk: f64, flip: f64) -> LibraryEvaluation {
        LibraryEvaluation {
            clips: vec![clip("walk", walk), clip("backflip", flip)],
            clips_at_threshold: 0,
            clip_fraction: 0.0,
            episodes_pass: false,
            all_clips_pass: false,
        }
    }

    fn pixels(png_bytes: &[u8]) -> (u32, u32, Vec<u8>) {
        let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
        let mut reader = decoder.read_info().expect("png");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("frame");
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    #[test]
    fn the_chart_paints_each_clip_by_its_success_over_time() {
        // walk learnt from the 3rd evaluation on, backflip never.
        let records: Vec<IterationRecord> = (1..=10)
            .map(|i| record(i, Some(library(if i >= 3 { 1.0 } else { 0.0 }, 0.0))))
            .collect();
        let png = clips_chart_png(&records, "library (seed 0)")
            .expect("a library run")
            .expect("drawn");
        let (w, h, rgb) = pixels(&png);
        assert_eq!((w, h), (CHART_WIDTH, chart_height(2)));
        let count = |c: RGBColor| {
            rgb.chunks_exact(3)
                .filter(|p| p[0] == c.0 && p[1] == c.1 && p[2] == c.2)
                .count()
        };
        let (red, green) = (count(success_color(0.0)), count(success_color(1.0)));
        // backflip's row is red throughout, walk's red for 2 of 10 columns: red covers
        // more than green, and both cover real areas, not a swatch.
        assert!(green > 20_000, "green {green}");
        assert!(red > green, "red {red} green {green}");
    }

    #[test]
    fn no_chart_without_a_library_evaluation_and_colors_run_red_to_green() {
        let records: Vec<IterationRecord> = (1..=3).map(|i| record(i, None)).collect();
        assert!(clips_chart_png(&records, "walk").is_none());
        assert!(clips_chart_png(&[], "none").is_none());
        assert_eq!(success_color(0.0), RGBColor(200, 45, 40));
        assert_eq!(success_color(0.5), RGBColor(235, 200, 60));
        assert_eq!(success_color(1.0), RGBColor(40, 155, 70));
        assert_eq!(success_color(7.0), success_color(1.0));
        assert_eq!(success_color(f64::NAN), RGBColor(190, 190, 190));
    }
}
