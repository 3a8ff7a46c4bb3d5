//! Executed end-effector paths drawn over the task layout (PNG, no text so that no font is
//! needed). Obstacles are red, goals green, objects blue (filled at the start, outlined at the
//! end of the episode), walls grey; each path has its own colour, starts at a dot and, if the
//! episode failed, ends at a black cross.
use super::KeptPath;
use crate::tasks::{LayoutItem, Role, Shape};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// Half width of the plotted square, metres.
const VIEW: f64 = 2.2;

type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn err(e: impl std::fmt::Debug) -> anyhow::Error {
    anyhow::anyhow!("plot: {e:?}")
}

fn clamp(p: [f64; 2]) -> (f64, f64) {
    (p[0].clamp(-VIEW, VIEW), p[1].clamp(-VIEW, VIEW))
}

fn draw_item(chart: &mut Chart<'_, '_>, item: &LayoutItem, filled: bool) -> anyhow::Result<()> {
    let color = match item.role {
        Role::Obstacle => RGBColor(220, 60, 60),
        Role::Goal => RGBColor(40, 170, 60),
        Role::Object => RGBColor(60, 90, 220),
        Role::Wall => RGBColor(110, 110, 110),
    };
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
                    .map_err(err)?;
            } else {
                let mut closed = points.clone();
                closed.extend(points.first().copied());
                chart
                    .draw_series(std::iter::once(PathElement::new(closed, style)))
                    .map_err(err)?;
            }
        }
        Shape::Rect { min, max } => {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [clamp(min), clamp(max)],
                    style,
                )))
                .map_err(err)?;
        }
    }
    Ok(())
}

/// Draws `paths` over their layouts into a `size` x `size` PNG at `out`.
pub fn plot_paths(out: &Path, paths: &[KeptPath], size: u32) -> anyhow::Result<()> {
    let root = BitMapBackend::new(out, (size, size)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .margin(8)
        .build_cartesian_2d(-VIEW..VIEW, -VIEW..VIEW)
        .map_err(err)?;
    // Frame and axes through the origin instead of a labelled mesh.
    let frame = [
        (-VIEW, -VIEW),
        (VIEW, -VIEW),
        (VIEW, VIEW),
        (-VIEW, VIEW),
        (-VIEW, -VIEW),
    ];
    chart
        .draw_series(std::iter::once(PathElement::new(
            frame.to_vec(),
            BLACK.stroke_width(1),
        )))
        .map_err(err)?;
    for axis in [[(-VIEW, 0.0), (VIEW, 0.0)], [(0.0, -VIEW), (0.0, VIEW)]] {
        chart
            .draw_series(std::iter::once(PathElement::new(
                axis.to_vec(),
                BLACK.mix(0.15),
            )))
            .map_err(err)?;
    }
    for kept in paths {
        for item in &kept.layout_start {
            draw_item(&mut chart, item, true)?;
        }
        for item in kept.layout_end.iter().filter(|i| i.role == Role::Object) {
            draw_item(&mut chart, item, false)?;
        }
    }
    for (index, kept) in paths.iter().enumerate() {
        let color = Palette99::pick(index).to_rgba();
        let points: Vec<(f64, f64)> = kept.ee_path.iter().map(|&p| clamp(p)).collect();
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                color.stroke_width(2),
            ))
            .map_err(err)?;
        if let Some(&start) = points.first() {
            chart
                .draw_series(std::iter::once(Circle::new(start, 4, color.filled())))
                .map_err(err)?;
        }
        if let (false, Some(&end)) = (kept.success, points.last()) {
            chart
                .draw_series(std::iter::once(Cross::new(end, 6, BLACK.stroke_width(2))))
                .map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}
