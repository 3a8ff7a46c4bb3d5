//! `frmd latency`: wall time per action chunk of several float policies side by side, in one
//! process, batch 1, after warm-up (DESIGN.md section 6: median and p99 over >= 200 calls).
use crate::eval::policy::{Policy, PolicyInput};
use crate::policy::float::FloatPolicy;
use crate::diffusion::samplers::Solver;
use anyhow::Context;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct LatencyArgs {
    /// Policies as DIR[:STEPS[:SOLVER]], e.g. `student:1`, `teacher:10:heun`, `dp:100`, `dp:10`.
    #[arg(long = "policy", required = true)]
    pub policies: Vec<String>,
    /// Timed calls per policy.
    #[arg(long, default_value_t = 200)]
    pub calls: usize,
    /// Untimed warm-up calls per policy.
    #[arg(long, default_value_t = 20)]
    pub warmup: usize,
    /// Write the results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn parse_spec(spec: &str) -> anyhow::Result<(PathBuf, Option<usize>, Option<Solver>)> {
    let mut parts = spec.split(':');
    let dir = PathBuf::from(parts.next().unwrap_or_default());
    let steps = parts.next().map(|s| s.parse::<usize>().with_context(|| format!("bad step count in `{spec}`"))).transpose()?;
    let solver = parts.next().map(Solver::parse).transpose()?;
    Ok((dir, steps, solver))
}

pub fn run(args: LatencyArgs) -> anyhow::Result<ExitCode> {
    let mut rows = Vec::new();
    println!("{:<40} {:>12} {:>12} {:>8}", "policy", "median us", "p99 us", "calls");
    for spec in &args.policies {
        let (dir, steps, solver) = parse_spec(spec)?;
        let mut policy = FloatPolicy::load(&dir, steps, solver).with_context(|| format!("loading {}", dir.display()))?;
        let (obs_dim, action_dim, history) = policy.input_sizes();
        let obs = vec![vec![0.1f32; obs_dim]; history];
        let (prev, rate) = (vec![0.0f32; action_dim], vec![0.0f32; action_dim]);
        let input = PolicyInput { obs_history: &obs, prev_action: &prev, prev_rate: &rate };
        policy.reset(0);
        for _ in 0..args.warmup {
            policy.act(&input)?;
        }
        let mut times = Vec::with_capacity(args.calls);
        for _ in 0..args.calls {
            let start = Instant::now();
            policy.act(&input)?;
            times.push(start.elapsed().as_secs_f64() * 1e6);
        }
        times.sort_by(|a, b| a.total_cmp(b));
        let pick = |q: f64| times.get(((q * times.len() as f64).ceil() as usize).saturating_sub(1)).copied().unwrap_or(f64::NAN);
        let (median, p99) = (pick(0.5), pick(0.99));
        let name = format!("{} ({})", policy.name(), dir.display());
        println!("{name:<40} {median:>12.1} {p99:>12.1} {:>8}", times.len());
        rows.push(serde_json::json!({ "policy": policy.name(), "ckpt": dir.display().to_string(), "median_us": median, "p99_us": p99, "calls": times.len() }));
    }
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into());
    println!("batch 1, RAYON_NUM_THREADS={threads}");
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&serde_json::json!({ "threads": threads, "results": rows }))?)?;
    }
    Ok(ExitCode::SUCCESS)
}
