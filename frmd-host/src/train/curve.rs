//! Learning-curve PNG: top panel log10(loss) against step, bottom panel closed-loop success rate
//! (0..1) against step. No text is drawn (the plotting backend has no fonts); the numbers are in
//! frmd.json's training summary.
use plotters::prelude::*;
use std::path::Path;

fn err(e: impl std::fmt::Debug) -> anyhow::Error {
    anyhow::anyhow!("learning-curve plot: {e:?}")
}

/// Draws `loss` (step, loss) and `success` (step, rate) into `out` (PNG, 800 x 600).
pub fn plot_learning_curve(out: &Path, loss: &[(usize, f64)], success: &[(usize, f64)]) -> anyhow::Result<()> {
    let root = BitMapBackend::new(out, (800, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, bottom) = root.split_vertically(380);
    let max_step = loss.iter().map(|p| p.0).chain(success.iter().map(|p| p.0)).max().unwrap_or(1).max(1) as f64;
    let logs: Vec<(f64, f64)> = loss.iter().filter(|p| p.1 > 0.0).map(|&(s, l)| (s as f64, l.log10())).collect();
    let (lo, hi) = logs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (lo, hi) = if lo.is_finite() { (lo.floor(), hi.ceil().max(lo.floor() + 1.0)) } else { (-1.0, 0.0) };
    let mut chart = ChartBuilder::on(&top).margin(20).build_cartesian_2d(0.0..max_step, lo..hi).map_err(err)?;
    for decade in (lo as i64)..=(hi as i64) {
        let y = decade as f64;
        chart.draw_series(LineSeries::new([(0.0, y), (max_step, y)], RGBColor(220, 220, 220))).map_err(err)?;
    }
    chart.draw_series(LineSeries::new(logs, BLUE.stroke_width(2))).map_err(err)?;
    let mut chart = ChartBuilder::on(&bottom).margin(20).build_cartesian_2d(0.0..max_step, 0.0..1.0).map_err(err)?;
    for level in [0.0, 0.25, 0.5, 0.75, 1.0] {
        chart.draw_series(LineSeries::new([(0.0, level), (max_step, level)], RGBColor(220, 220, 220))).map_err(err)?;
    }
    let points: Vec<(f64, f64)> = success.iter().map(|&(s, r)| (s as f64, r)).collect();
    chart.draw_series(LineSeries::new(points.clone(), GREEN.stroke_width(2))).map_err(err)?;
    chart.draw_series(points.into_iter().map(|p| Circle::new(p, 4, GREEN.filled()))).map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
