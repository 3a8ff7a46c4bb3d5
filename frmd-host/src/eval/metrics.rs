//! Metric definitions of docs/design.md section 6: curvature-based non-smooth transitions, RMS jerk,
//! Wilson score intervals and latency percentiles.

/// Curvature above which a transition counts as non-smooth, rad/m.
pub const NON_SMOOTH_CURVATURE: f64 = 1.0;
/// Segments shorter than this are skipped (merged into the next one), metres.
pub const MIN_SEGMENT: f64 = 1e-4;

/// Curvatures kappa_i = theta_i / (0.5 (|p_i - p_{i-1}| + |p_{i+1} - p_i|)) at the interior points
/// of `path`, rad/m. Points closer than [`MIN_SEGMENT`] to the previously kept point are dropped
/// first, so a pause (zero-length steps) neither creates nor hides a turn.
pub fn curvatures(path: &[[f64; 2]]) -> Vec<f64> {
    let mut kept: Vec<[f64; 2]> = Vec::with_capacity(path.len());
    for &p in path {
        match kept.last() {
            Some(&q) if (p[0] - q[0]).hypot(p[1] - q[1]) < MIN_SEGMENT => {}
            _ => kept.push(p),
        }
    }
    kept.windows(3)
        .map(|w| {
            let a = [w[1][0] - w[0][0], w[1][1] - w[0][1]];
            let b = [w[2][0] - w[1][0], w[2][1] - w[1][1]];
            let theta = (a[0] * b[1] - a[1] * b[0])
                .abs()
                .atan2(a[0] * b[0] + a[1] * b[1]);
            theta / (0.5 * (a[0].hypot(a[1]) + b[0].hypot(b[1])))
        })
        .collect()
}

/// Number of non-smooth transitions (curvature above [`NON_SMOOTH_CURVATURE`]) along `path`.
pub fn non_smooth_transitions(path: &[[f64; 2]]) -> usize {
    curvatures(path)
        .into_iter()
        .filter(|&k| k > NON_SMOOTH_CURVATURE)
        .count()
}

/// Root-mean-square jerk of a path sampled every `dt` seconds (third finite difference),
/// units/s^3; 0 for fewer than four points.
pub fn rms_jerk(path: &[[f64; 2]], dt: f64) -> f64 {
    if path.len() < 4 || dt <= 0.0 {
        return 0.0;
    }
    let scale = 1.0 / (dt * dt * dt);
    let sum: f64 = path
        .windows(4)
        .map(|w| {
            let jx = (w[3][0] - 3.0 * w[2][0] + 3.0 * w[1][0] - w[0][0]) * scale;
            let jy = (w[3][1] - 3.0 * w[2][1] + 3.0 * w[1][1] - w[0][1]) * scale;
            jx * jx + jy * jy
        })
        .sum();
    (sum / (path.len() - 3) as f64).sqrt()
}

/// 95 % Wilson score interval for `successes` out of `trials` ([0, 1] when there are no trials).
pub fn wilson_interval(successes: usize, trials: usize) -> [f64; 2] {
    if trials == 0 {
        return [0.0, 1.0];
    }
    let z = 1.959_963_984_540_054_f64;
    let n = trials as f64;
    let p = successes as f64 / n;
    let denom = 1.0 + z * z / n;
    let center = (p + z * z / (2.0 * n)) / denom;
    let half = z / denom * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    [(center - half).max(0.0), (center + half).min(1.0)]
}

/// The `q`-quantile (0..=1) of `values` by the nearest-rank method; 0 for no values.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = (q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        0.0
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn polyline(corners: &[[f64; 2]], step: f64) -> Vec<[f64; 2]> {
        let mut out = vec![corners[0]];
        for w in corners.windows(2) {
            let (a, b) = (w[0], w[1]);
            let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / step).round() as usize;
            for k in 1..=n {
                let u = k as f64 / n as f64;
                out.push([a[0] + (b[0] - a[0]) * u, a[1] + (b[1] - a[1]) * u]);
            }
        }
        out
    }

    #[test]
    fn straight_line_has_no_kinks() {
        let line = polyline(&[[0.0, 0.0], [2.0, 1.0]], 0.05);
        assert!(line.len() > 40);
        assert_eq!(non_smooth_transitions(&line), 0);
    }

    #[test]
    fn square_counts_its_corners() {
        // Start mid-edge and go once around: four corners, each a 90-degree turn.
        let square = polyline(
            &[
                [0.5, 0.0],
                [1.0, 0.0],
                [1.0, 1.0],
                [0.0, 1.0],
                [0.0, 0.0],
                [0.5, 0.0],
            ],
            0.1,
        );
        assert_eq!(non_smooth_transitions(&square), 4);
        // Open square path starting at a corner: its three interior corners.
        let open = polyline(
            &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]],
            0.1,
        );
        assert_eq!(non_smooth_transitions(&open), 3);
        let kappa = curvatures(&square).into_iter().fold(0.0, f64::max);
        assert!(
            (kappa - std::f64::consts::FRAC_PI_2 / 0.1).abs() < 1e-9,
            "max curvature {kappa}"
        );
    }

    #[test]
    fn large_circle_is_smooth_small_circle_is_not() {
        let circle = |radius: f64, n: usize| -> Vec<[f64; 2]> {
            (0..=n)
                .map(|k| {
                    let a = k as f64 / n as f64 * std::f64::consts::TAU;
                    [radius * a.cos(), radius * a.sin()]
                })
                .collect()
        };
        // Curvature 1/radius: 0.5 rad/m for radius 2, 2 rad/m for radius 0.5.
        assert_eq!(non_smooth_transitions(&circle(2.0, 200)), 0);
        assert_eq!(non_smooth_transitions(&circle(0.5, 200)), 199);
    }

    #[test]
    fn pauses_are_skipped_not_counted() {
        let mut path = polyline(&[[0.0, 0.0], [1.0, 0.0]], 0.1);
        let last = *path.last().unwrap();
        path.extend(std::iter::repeat_n(last, 5));
        path.extend(polyline(&[last, [2.0, 0.0]], 0.1).into_iter().skip(1));
        assert_eq!(non_smooth_transitions(&path), 0);
    }

    #[test]
    fn jerk_of_cubic_motion_is_constant() {
        // x = t^3 has jerk 6 everywhere.
        let dt = 0.1;
        let path: Vec<[f64; 2]> = (0..20).map(|k| [(k as f64 * dt).powi(3), 0.0]).collect();
        assert!((rms_jerk(&path, dt) - 6.0).abs() < 1e-6);
        assert_eq!(rms_jerk(&path[..3], dt), 0.0);
    }

    #[test]
    fn wilson_matches_known_values() {
        // 45 of 50: [0.786, 0.957] (standard tables).
        let [lo, hi] = wilson_interval(45, 50);
        assert!(
            (lo - 0.7864).abs() < 1e-3 && (hi - 0.9565).abs() < 1e-3,
            "{lo} {hi}"
        );
        let [lo, hi] = wilson_interval(50, 50);
        assert!(lo > 0.92 && hi == 1.0);
        assert_eq!(wilson_interval(0, 0), [0.0, 1.0]);
    }

    #[test]
    fn quantiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), 50.0);
        assert_eq!(quantile(&v, 0.99), 99.0);
        assert_eq!(quantile(&[], 0.5), 0.0);
    }
}
