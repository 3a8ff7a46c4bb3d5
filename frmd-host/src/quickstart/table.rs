//! The quickstart result table (plain text, also written to `summary.txt`).
use super::QuickstartSummary;
use std::fmt::Write;

/// Renders the table, the stage timings and the artifact paths.
pub fn render(s: &QuickstartSummary) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "FRMD quickstart: task `{}`, {} evaluation episodes per method (seeds disjoint from the demonstrations)", s.task, s.episodes);
    let _ = writeln!(
        t,
        "{:<17} {:>24} {:>22} {:>11} {:>10} {:>24}",
        "method",
        "success [95 % CI]",
        "latency us med / p99",
        "non-smooth",
        "RMS jerk",
        "quantized vs float"
    );
    for row in &s.rows {
        match (&row.report, &row.missing) {
            (Some(r), _) => {
                let success = format!(
                    "{:.1} % [{:.1}, {:.1}]",
                    100.0 * r.success_rate,
                    100.0 * r.success_ci95[0],
                    100.0 * r.success_ci95[1]
                );
                let latency = format!("{:.1} / {:.1}", r.latency_us_median, r.latency_us_p99);
                let _ = writeln!(
                    t,
                    "{:<17} {:>24} {:>22} {:>11.2} {:>10.2} {:>24}",
                    row.method,
                    success,
                    latency,
                    r.non_smooth_ee_mean,
                    r.rms_jerk_mean,
                    row.quantized_error.as_deref().unwrap_or("-")
                );
            }
            (None, missing) => {
                let _ = writeln!(
                    t,
                    "{:<17} {}",
                    row.method,
                    missing.as_deref().unwrap_or("not evaluated")
                );
            }
        }
    }
    let _ = writeln!(
        t,
        "latency: wall time per chunk in closed loop (batch 1, after warm-up), RAYON_NUM_THREADS={}; \
         non-smooth: transitions with curvature > 1 rad/m per episode (end effector); RMS jerk in m/s^3",
        s.threads
    );
    let stages: Vec<String> = s
        .stage_seconds
        .iter()
        .map(|(what, secs)| format!("{what}: {secs:.0} s"))
        .collect();
    let _ = writeln!(
        t,
        "wall time {:.0} s ({})",
        s.total_seconds,
        stages.join("; ")
    );
    let _ = writeln!(t, "artifacts:");
    for (what, path) in &s.artifacts {
        let _ = writeln!(t, "  {:<36} {}", what, path.display());
    }
    t
}
