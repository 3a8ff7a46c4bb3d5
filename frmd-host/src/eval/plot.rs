//! Executed end-effector paths of an evaluation drawn over the task layout (PNG): axes in metres
//! with tick labels, a title with task, method and success rate, a legend, and each path coloured
//! by its episode's outcome (success blue, failure orange, failures end at a black cross; every
//! path starts at a dot). Obstacles are red, goals green, objects blue (filled at the start,
//! outlined at the end of the episode), walls grey.
//!
//! Text is drawn with DejaVu Sans, embedded in the binary (the `dejavu` crate; Bitstream Vera
//! license), so plots need no system fonts.
use super::{EvalReport, KeptPath};
use crate::tasks::{LayoutItem, Role, Shape};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// Episodes whose paths a plot shows by default (`frmd eval --plot-episodes`, the quick start).
pub const PLOTTED_EPISODES: usize = 10;

/// Half width of the plotted square, metres.
const VIEW: f64 = 2.2;
/// Width and height of a path plot, pixels.
const SIZE: (u32, u32) = (820, 880);

/// Font family every plot uses.
pub(crate) const FONT: &str = "sans-serif";
const SUCCESS: RGBColor = RGBColor(30, 100, 220);
const FAILURE: RGBColor = RGBColor(240, 120, 0);

type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Maps a plotters error to an error naming the plot.
pub(crate) fn plot_err(e: impl std::fmt::Display) -> anyhow::Error {
    let text = e.to_string();
    anyhow::anyhow!("plot: {}", text.lines().next().unwrap_or_default())
}

/// Registers the embedded font with plotters (once per process).
pub(crate) fn register_font() -> anyhow::Result<()> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    anyhow::ensure!(ok, "plot: the embedded DejaVu Sans font did not load");
    Ok(())
}

fn clamp(p: [f64; 2]) -> (f64, f64) {
    (p[0].clamp(-VIEW, VIEW), p[1].clamp(-VIEW, VIEW))
}

fn role_color(role: Role) -> RGBColor {
    match role {
        Role::Obstacle => RGBColor(220, 60, 60),
        Role::Goal => RGBColor(40, 170, 60),
        Role::Object => RGBColor(60, 90, 220),
        Role::Wall => RGBColor(110, 110, 110),
    }
}

fn role_label(role: Role) -> &'static str {
    match role {
        Role::Obstacle => "obstacle",
        Role::Goal => "goal",
        Role::Object => "object (filled: start, outline: end)",
        Role::Wall => "wall",
    }
}

fn draw_item(chart: &mut Chart<'_, '_>, item: &LayoutItem, filled: bool) -> anyhow::Result<()> {
    let color = role_color(item.role);
    let style = if filled {
        color.mix(0.25).filled()
    } else {
        color.stroke_width(2)
    };
    match item.shape {
        Shape::Disc { center, radius } => {
            let points: Vec<(f64, f64)> = (0..48)
                .map(|k| {
                    let a = k as f64 / 48.0 * std::f64::consts::TAU;
                    clamp([center[0] + radius * a.cos(), center[1] + radius * a.sin()])
                })
                .collect();
            if filled {
                chart
                    .draw_series(std::iter::once(Polygon::new(points, style)))
                    .map_err(plot_err)?;
            } else {
                let mut closed = points.clone();
                closed.extend(points.first().copied());
                chart
                    .draw_series(std::iter::once(PathElement::new(closed, style)))
                    .map_err(plot_err)?;
            }
        }
        Shape::Rect { min, max } => {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [clamp(min), clamp(max)],
                    style,
                )))
                .map_err(plot_err)?;
        }
    }
    Ok(())
}

/// Adds a legend entry drawn as a filled square of `color` (layout items).
fn legend_swatch(chart: &mut Chart<'_, '_>, label: &str, color: RGBColor) -> anyhow::Result<()> {
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
        .map_err(plot_err)?
        .label(label)
        .legend(move |(x, y)| {
            Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.mix(0.5).filled())
        });
    Ok(())
}

/// Draws the kept paths of `report` over their layouts into a PNG at `out`.
/// The file is written atomically (`frmd_formats::artifact`).
pub fn plot_paths(out: &Path, report: &EvalReport) -> anyhow::Result<()> {
    frmd_formats::artifact::write_atomic_with(out, |tmp| draw_paths(tmp, report))
}

fn draw_paths(out: &Path, report: &EvalReport) -> anyhow::Result<()> {
    register_font()?;
    let paths: &[KeptPath] = &report.kept_paths;
    let root = BitMapBackend::new(out, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let title = format!(
        "{}: {}, success {:.1} % ({} of {} episodes)",
        report.task,
        report.policy,
        100.0 * report.success_rate,
        report.successes,
        report.episodes
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 22))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d(-VIEW..VIEW, -VIEW..VIEW)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc("y [m]")
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;
    let mut roles: Vec<Role> = Vec::new();
    for kept in paths {
        for item in &kept.layout_start {
            draw_item(&mut chart, item, true)?;
            roles.push(item.role);
        }
        for item in kept.layout_end.iter().filter(|i| i.role == Role::Object) {
            draw_item(&mut chart, item, false)?;
        }
    }
    for role in [Role::Goal, Role::Obstacle, Role::Object, Role::Wall] {
        if roles.contains(&role) {
            legend_swatch(&mut chart, role_label(role), role_color(role))?;
        }
    }
    for (outcome, color) in [(true, SUCCESS), (false, FAILURE)] {
        let mine: Vec<&KeptPath> = paths.iter().filter(|k| k.success == outcome).collect();
        for kept in &mine {
            let points: Vec<(f64, f64)> = kept.ee_path.iter().map(|&p| clamp(p)).collect();
            chart
                .draw_series(LineSeries::new(
                    points.iter().copied(),
                    color.stroke_width(2),
                ))
                .map_err(plot_err)?;
            if let Some(&start) = points.first() {
                chart
                    .draw_series(std::iter::once(Circle::new(start, 4, color.filled())))
                    .map_err(plot_err)?;
            }
            if let (false, Some(&end)) = (outcome, points.last()) {
                chart
                    .draw_series(std::iter::once(Cross::new(end, 6, BLACK.stroke_width(2))))
                    .map_err(plot_err)?;
            }
        }
        if !mine.is_empty() {
            let label = format!(
                "{} ({} of {} shown)",
                if outcome {
                    "success"
                } else {
                    "failure, ends at x"
                },
                mine.len(),
                paths.len()
            );
            chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                .map_err(plot_err)?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 14, y)], color.stroke_width(3))
                });
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .draw()
        .map_err(plot_err)?;
    root.present().map_err(plot_err)?;
    Ok(())
}
