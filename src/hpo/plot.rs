//! `trajectory.png`: the best objective against cycle as a step line, and every candidate as a
//! point (failed candidates, scored at the budget, as crosses); below it, each candidate's
//! average pose error at the end of its trials (mean over seeds), which shows a search's
//! progress while every candidate still fails at the budget. Drawn into a pixel buffer with an embedded font, so
//! it needs no system fonts or libraries.

use plotters::prelude::*;

use crate::hpo::error::HpoError;
use crate::hpo::record::{CycleRecord, CycleStatus};

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 600;

fn plot_error(e: impl std::fmt::Display) -> HpoError {
    HpoError::Plot {
        problem: e.to_string(),
    }
}

/// The trajectory plot as PNG bytes.
pub fn trajectory_png(
    history: &[CycleRecord],
    title: &str,
    budget_s: f64,
) -> Result<Vec<u8>, HpoError> {
    // (cycle, objective, pose error at the trials' end (NaN: none), succeeded)
    let mut points: Vec<(f64, f64, f64, bool)> = Vec::new();
    for record in history.iter().filter(|r| r.status != CycleStatus::Skipped) {
        for c in &record.candidates {
            points.push((
                f64::from(record.cycle),
                c.objective_s,
                c.rank().ape_m.unwrap_or(f64::NAN),
                c.successes > 0 && c.objective_s < budget_s,
            ));
        }
    }
    // Corners only: a thick polyline through collinear points draws bumps.
    let mut best_line: Vec<(f64, f64)> = Vec::new();
    for record in history {
        let x = f64::from(record.cycle);
        match best_line.last() {
            None => best_line.push((x, record.best.objective_s)),
            Some(&(_, previous)) if previous != record.best.objective_s => {
                best_line.push((x, previous));
                best_line.push((x, record.best.objective_s));
            }
            Some(_) => {}
        }
    }
    if let (Some(last), Some(&(x, y))) = (history.last(), best_line.last())
        && x != f64::from(last.cycle)
    {
        best_line.push((f64::from(last.cycle), y));
    }
    let last_cycle = history.last().map_or(1, |r| r.cycle.max(1));
    let y_max = points
        .iter()
        .map(|p| p.1)
        .chain(best_line.iter().map(|p| p.1))
        .fold(budget_s, f64::max);
    let y_hi = if y_max.is_finite() && y_max > 0.0 {
        y_max * 1.05
    } else {
        1.0
    };

    let x_range = -0.5f64..f64::from(last_cycle) + 0.5;
    let ok = RGBColor(60, 110, 200);
    let failed = RGBColor(210, 60, 50);
    crate::plot::render_png(WIDTH, HEIGHT, plot_error, |root| {
        let (upper, lower) = root.split_vertically(HEIGHT * 2 / 3);
        let mut chart = ChartBuilder::on(&upper)
            .caption(title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(x_range.clone(), 0f64..y_hi)
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc("cycle")
            .x_labels((last_cycle as usize + 1).min(21))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .light_line_style(RGBColor(235, 235, 235))
            .y_desc("median time to success (s)")
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .draw()
            .map_err(plot_error)?;
        let best = RGBColor(20, 20, 20);
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.3)
                    .map(|&(x, y, _, _)| Circle::new((x, y), 4, ok.filled())),
            )
            .map_err(plot_error)?
            .label("candidate")
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, ok.filled()));
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| !p.3)
                    .map(|&(x, y, _, _)| Cross::new((x, y), 5, failed.stroke_width(2))),
            )
            .map_err(plot_error)?
            .label("failed candidate (budget)")
            .legend(move |(x, y)| Cross::new((x + 10, y), 5, failed.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(
                best_line.iter().copied(),
                best.stroke_width(3),
            ))
            .map_err(plot_error)?
            .label("best so far")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], best.stroke_width(3))
            });
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(plot_error)?;

        let ape_hi = points
            .iter()
            .map(|p| p.2)
            .filter(|a| a.is_finite())
            .fold(0.0f64, f64::max)
            .max(0.01)
            * 1.1;
        let mut rates = ChartBuilder::on(&lower)
            .margin(16)
            .x_label_area_size(40)
            .y_label_area_size(72)
            .build_cartesian_2d(x_range.clone(), 0f64..ape_hi)
            .map_err(plot_error)?;
        rates
            .configure_mesh()
            .x_labels((last_cycle as usize + 1).min(21))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_labels(3)
            .light_line_style(RGBColor(235, 235, 235))
            .y_desc("pose error at end (m)")
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .draw()
            .map_err(plot_error)?;
        rates
            .draw_series(points.iter().filter(|p| p.2.is_finite()).map(
                |&(x, _, ape, succeeded)| {
                    let style = if succeeded {
                        ok.filled()
                    } else {
                        failed.filled()
                    };
                    Circle::new((x, ape), 4, style)
                },
            ))
            .map_err(plot_error)?;
        Ok(())
    })
}
