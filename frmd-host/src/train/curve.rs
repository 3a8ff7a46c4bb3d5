//! Learning-curve PNG of a training run: the loss (log scale) against the step on top, the
//! closed-loop success rate of the evaluations during training below (when there were any),
//! with axes, tick labels and a title naming task and role. The numbers are also in frmd.json's
//! training summary.
use crate::checkpoint::Role;
use crate::eval::plot::{plot_err, register_font, FONT};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Width and height of the plot, pixels.
const SIZE: (u32, u32) = (820, 640);

/// Draws `loss` (step, mean loss) and `success` (step, success rate) of a `role` run on `task`
/// into the PNG `out`.
pub fn plot_learning_curve(
    out: &Path,
    task: &str,
    role: Role,
    loss: &[(usize, f64)],
    success: &[(usize, f64)],
) -> anyhow::Result<()> {
    let title = format!("{task}: {role} training");
    frmd_formats::artifact::write_atomic_with(out, |tmp| draw_curve(tmp, &title, loss, success))
}

fn draw_curve(
    out: &Path,
    title: &str,
    loss: &[(usize, f64)],
    success: &[(usize, f64)],
) -> anyhow::Result<()> {
    register_font()?;
    let root = BitMapBackend::new(out, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let root = root.titled(title, (FONT, 22)).map_err(plot_err)?;
    let (top, bottom) = root.split_vertically(330);
    let max_step = loss
        .iter()
        .map(|p| p.0)
        .chain(success.iter().map(|p| p.0))
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let logs: Vec<(f64, f64)> = loss
        .iter()
        .filter(|p| p.1 > 0.0)
        .map(|&(s, l)| (s as f64, l.log10()))
        .collect();
    let (lo, hi) = logs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.1), b.max(p.1))
        });
    let (lo, hi) = if lo.is_finite() {
        (lo.floor(), hi.ceil().max(lo.floor() + 1.0))
    } else {
        (-1.0, 0.0)
    };
    let mut chart = panel(
        &top,
        max_step,
        lo..hi,
        "training loss",
        (hi - lo) as usize + 1,
        &|v| format!("1e{}", v.round()),
    )?;
    chart
        .draw_series(LineSeries::new(logs, BLUE.stroke_width(2)))
        .map_err(plot_err)?;
    let y_desc = if success.is_empty() {
        "success [%] (no evaluation during training)"
    } else {
        "closed-loop success [%]"
    };
    let mut chart = panel(&bottom, max_step, 0.0..100.0, y_desc, 5, &|v| {
        format!("{v:.0}")
    })?;
    let points: Vec<(f64, f64)> = success
        .iter()
        .map(|&(s, r)| (s as f64, 100.0 * r))
        .collect();
    let green = RGBColor(30, 150, 60);
    chart
        .draw_series(LineSeries::new(points.clone(), green.stroke_width(2)))
        .map_err(plot_err)?;
    chart
        .draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 4, green.filled())),
        )
        .map_err(plot_err)?;
    root.present().map_err(plot_err)?;
    Ok(())
}

type Panel<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// One panel over steps `0..max_step`: axes, `y_labels` tick labels on the y axis written by
/// `y_format`, and light grid lines.
fn panel<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    max_step: f64,
    y: std::ops::Range<f64>,
    y_desc: &str,
    y_labels: usize,
    y_format: &dyn Fn(&f64) -> String,
) -> anyhow::Result<Panel<'a, 'b>> {
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..max_step, y)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("step")
        .y_desc(y_desc)
        .y_labels(y_labels)
        .y_label_formatter(y_format)
        .x_label_formatter(&|v| format!("{v:.0}"))
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(plot_err)?;
    Ok(chart)
}
