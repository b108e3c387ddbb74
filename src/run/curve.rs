//! `curve.png`: the learning curve of a run: mean episode length (left axis, every iteration)
//! and the evaluation (right axis, every evaluation) against active training time: a tracking
//! run's success rate with the success threshold as a dashed line, or the task's own score (a
//! goal run's goals per episode, the last fall rate in the legend). Drawn into a pixel buffer with the embedded
//! font (as `hpo/plot.rs`), so it needs no system fonts or libraries.

use std::path::Path;

use plotters::prelude::*;

use super::error::RunError;
use super::metrics::IterationRecord;
use crate::env::TaskScore;
use crate::files::write_bytes_atomically;

pub const CURVE_WIDTH: u32 = 1000;
pub const CURVE_HEIGHT: u32 = 600;
/// Series colors (tests look for them in the image).
pub const EPISODE_LENGTH_COLOR: RGBColor = RGBColor(40, 100, 200);
pub const SUCCESS_RATE_COLOR: RGBColor = RGBColor(215, 80, 30);
pub const TASK_SCORE_COLOR: RGBColor = RGBColor(30, 150, 70);

/// What the curve's right axis shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RightAxis {
    /// A tracking run's evaluation success rate, with `threshold` (the run's success rate)
    /// dashed.
    SuccessRate { threshold: f64 },
    /// The task's own evaluation score (the goal task's goals per episode: it has no success
    /// rate).
    TaskScore,
}

/// The right axis's series: its points, label, color and upper bound.
struct RightSeries {
    points: Vec<(f64, f64)>,
    /// Evaluations that stopped once decided (`run.eval_early_stop`): their rates are lower
    /// bounds, drawn apart from the line.
    lower_bounds: Vec<(f64, f64)>,
    label: String,
    color: RGBColor,
    top: f64,
    threshold: Option<f64>,
}

fn right_series(records: &[IterationRecord], axis: RightAxis) -> RightSeries {
    let finite = |&(t, y): &(f64, f64)| t.is_finite() && y.is_finite();
    match axis {
        RightAxis::SuccessRate { threshold } => {
            let rates = |stopped: bool| -> Vec<(f64, f64)> {
                records
                    .iter()
                    .filter_map(|r| {
                        let e = r.evaluation.as_ref()?;
                        (e.stopped_at_step.is_some() == stopped)
                            .then_some((r.active_time_s, e.success_rate))
                    })
                    .filter(finite)
                    .collect()
            };
            RightSeries {
                points: rates(false),
                lower_bounds: rates(true),
                label: "success rate".to_owned(),
                color: SUCCESS_RATE_COLOR,
                top: 1.05,
                threshold: Some(threshold),
            }
        }
        RightAxis::TaskScore => {
            let scores: Vec<(f64, TaskScore)> = records
                .iter()
                .filter_map(|r| Some((r.active_time_s, r.task.as_ref()?.score()?)))
                .filter(|(t, s)| finite(&(*t, s.value)))
                .collect();
            let most = scores.iter().map(|(_, s)| s.value).fold(0.0, f64::max);
            let label = match scores.last() {
                Some((_, s)) => match &s.detail {
                    Some(detail) => format!("{} (last {:.2}, {detail})", s.name, s.value),
                    None => format!("{} (last {:.2})", s.name, s.value),
                },
                None => "task evaluation".to_owned(),
            };
            RightSeries {
                points: scores.iter().map(|(t, s)| (*t, s.value)).collect(),
                lower_bounds: Vec::new(),
                label,
                color: TASK_SCORE_COLOR,
                top: (most * 1.1).max(1.0),
                threshold: None,
            }
        }
    }
}
fn plot_error(e: impl std::fmt::Display) -> RunError {
    RunError::Plot(e.to_string())
}

/// The learning curve as PNG bytes. `max_episode_length` sets the left axis (the episode
/// length limit); `right` says what the right axis shows.
pub fn learning_curve_png(
    records: &[IterationRecord],
    title: &str,
    max_episode_length: f64,
    right: RightAxis,
) -> Result<Vec<u8>, RunError> {
    let finite = |x: f64| x.is_finite();
    let lengths: Vec<(f64, f64)> = records
        .iter()
        .map(|r| (r.active_time_s, r.mean_episode_length))
        .filter(|&(t, l)| finite(t) && finite(l))
        .collect();
    let series = right_series(records, right);
    let t_max = lengths
        .iter()
        .chain(&series.points)
        .map(|p| p.0)
        .fold(0.0, f64::max);
    let t_hi = if t_max > 0.0 { t_max * 1.02 } else { 1.0 };
    let l_max = lengths
        .iter()
        .map(|p| p.1)
        .fold(max_episode_length, f64::max);
    let l_hi = if l_max > 0.0 { l_max * 1.05 } else { 1.0 };

    crate::plot::render_png(CURVE_WIDTH, CURVE_HEIGHT, plot_error, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .right_y_label_area_size(72)
            .build_cartesian_2d(0f64..t_hi, 0f64..l_hi)
            .map_err(plot_error)?
            .set_secondary_coord(0f64..t_hi, 0f64..series.top);
        chart
            .configure_mesh()
            .x_desc("active training time (s)")
            .y_desc("mean episode length (control steps)")
            .y_label_formatter(&|y| format!("{y:.0}"))
            .light_line_style(RGBColor(235, 235, 235))
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .draw()
            .map_err(plot_error)?;
        chart
            .configure_secondary_axes()
            .y_desc(match right {
                RightAxis::SuccessRate { .. } => "evaluation success rate".to_owned(),
                RightAxis::TaskScore => format!(
                    "evaluation {}",
                    records
                        .iter()
                        .rev()
                        .find_map(|r| r.task.as_ref()?.score())
                        .map_or("score", |s| s.name)
                ),
            })
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .draw()
            .map_err(plot_error)?;
        chart
            .draw_series(LineSeries::new(
                lengths.iter().copied(),
                EPISODE_LENGTH_COLOR.stroke_width(2),
            ))
            .map_err(plot_error)?
            .label("episode length")
            .legend(|(x, y)| {
                PathElement::new(
                    vec![(x, y), (x + 20, y)],
                    EPISODE_LENGTH_COLOR.stroke_width(2),
                )
            });
        if let Some(threshold) = series.threshold {
            let grey = RGBColor(120, 120, 120);
            chart
                .draw_secondary_series(DashedLineSeries::new(
                    [(0.0, threshold), (t_hi, threshold)],
                    8,
                    6,
                    grey.stroke_width(1),
                ))
                .map_err(plot_error)?
                .label(format!("success threshold {threshold}"))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(1))
                });
        }
        let color = series.color;
        chart
            .draw_secondary_series(LineSeries::new(
                series.points.iter().copied(),
                color.stroke_width(2),
            ))
            .map_err(plot_error)?;
        chart
            .draw_secondary_series(
                series
                    .points
                    .iter()
                    .map(|&p| Circle::new(p, 4, color.filled())),
            )
            .map_err(plot_error)?
            .label(series.label.as_str())
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
        if !series.lower_bounds.is_empty() {
            chart
                .draw_secondary_series(
                    series
                        .lower_bounds
                        .iter()
                        .map(|&p| Circle::new(p, 3, color.stroke_width(1))),
                )
                .map_err(plot_error)?
                .label("stopped when out of reach (at least)")
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.stroke_width(1)));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .position(SeriesLabelPosition::LowerRight)
            .draw()
            .map_err(plot_error)?;
        Ok(())
    })
}

/// Draws the curve and replaces `path` with it atomically (a viewer never sees half a PNG).
pub fn write_learning_curve(
    path: &Path,
    records: &[IterationRecord],
    title: &str,
    max_episode_length: f64,
    right: RightAxis,
) -> Result<(), RunError> {
    let png = learning_curve_png(records, title, max_episode_length, right)?;
    write_bytes_atomically(path, &png).map_err(|e| RunError::io(path, e))
}
