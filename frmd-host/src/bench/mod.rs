//! Latency per action chunk of every policy kind side by side, in one process (what `frmd bench`
//! does): batch 1, after warm-up, median and p99 over >= 200 calls (docs/design.md section 6), with
//! the ratio of each row to the first row: the frmd-core int8 one-step policy (the candle
//! one-step student if the student cannot be exported). On x86-64 CPUs with AVX2 the int8 policy
//! is timed again with frmd-core's lower kernel levels (`... avx2` without AVX-VNNI,
//! `... portable`).
//!
//! By default it times the checkpoints `frmd quickstart` wrote (`runs/quickstart/{student,
//! teacher,dp}`): student 1 and 2 steps (candle, and frmd-core int8), teacher 10 Heun steps, DP
//! 100 (DDPM) and 10 (DDIM) steps, all with the same backbone. [`BenchConfig::policies`] times
//! other checkpoints instead (the frmd-core rows then export the first student among them), and
//! [`BenchConfig::synthetic`] times randomly initialized networks of a given backbone (latency
//! does not depend on the weights), which needs no checkpoint at all. [`fixtures`] builds such
//! networks for the benchmarks and instruction counts.
use crate::checkpoint::Role;
use crate::diffusion::samplers::Solver;
use crate::eval::metrics::quantile;
use crate::export::{export_student, ExportConfig};
use crate::models::BackboneConfig;
use crate::policy::float::{FloatPolicy, Sampler};
use crate::policy::int8::Int8Policy;
use crate::quickstart::QuickstartConfig;
use crate::tasks::{Policy, PolicyInput};
use anyhow::Context;
use frmd_core::policy::PolicyDims;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub mod fixtures;
pub mod stages;
#[cfg(test)]
mod tests;

/// What to time.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchConfig {
    /// Checkpoints to time (empty: student:1, teacher:10:heun, dp:100, dp:10 from `dir`).
    pub policies: Vec<PolicySpec>,
    /// Directory holding `student/`, `teacher/` and `dp/` checkpoints (as written by quickstart);
    /// the frmd-core rows export its student unless a `--policy` names a student checkpoint.
    pub dir: PathBuf,
    /// Time randomly initialized networks of `backbone` instead of checkpoints.
    pub synthetic: bool,
    /// Backbone of the synthetic networks.
    pub backbone: BackboneConfig,
    /// Timed calls per policy (at least 200 for the docs/design.md p99).
    pub calls: usize,
    /// Untimed warm-up calls per policy.
    pub warmup: usize,
}

impl Default for BenchConfig {
    /// The quick start's checkpoints and backbone, 200 timed calls after 20 warm-up calls.
    fn default() -> Self {
        let quickstart = QuickstartConfig::default();
        BenchConfig {
            policies: Vec::new(),
            dir: quickstart.out,
            synthetic: false,
            backbone: quickstart.backbone,
            calls: 200,
            warmup: 20,
        }
    }
}

/// A checkpoint to time with its sampler: `DIR[:STEPS[:SOLVER]]`, e.g.
/// `runs/quickstart/teacher:10:heun`.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicySpec {
    pub dir: PathBuf,
    pub steps: Option<usize>,
    pub solver: Option<Solver>,
}

impl std::str::FromStr for PolicySpec {
    type Err = anyhow::Error;

    fn from_str(spec: &str) -> anyhow::Result<Self> {
        let mut parts = spec.split(':');
        let dir = PathBuf::from(parts.next().unwrap_or_default());
        let steps = parts
            .next()
            .map(|s| {
                s.parse::<usize>()
                    .with_context(|| format!("bad step count in `{spec}`"))
            })
            .transpose()?;
        let solver = parts.next().map(Solver::parse).transpose()?;
        Ok(PolicySpec { dir, steps, solver })
    }
}

/// One timed policy.
#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    /// What ran, e.g. `candle student-1`.
    pub label: String,
    /// Backbone description, e.g. `mlp[256,256,256] silu`.
    pub backbone: String,
    /// Wall time per chunk, microseconds.
    pub median_us: f64,
    pub p99_us: f64,
    pub calls: usize,
}

/// A readable backbone description for tables.
pub fn backbone_label(backbone: &BackboneConfig) -> String {
    match backbone {
        BackboneConfig::Mlp { hidden, activation } => {
            let widths: Vec<String> = hidden.iter().map(|w| w.to_string()).collect();
            format!(
                "mlp[{}] {}",
                widths.join(","),
                format!("{activation:?}").to_lowercase()
            )
        }
        BackboneConfig::Transformer {
            layers,
            heads,
            width,
        } => format!("transformer {layers}x{heads}h {width}"),
    }
}

/// A fixed policy input of the right sizes (the values do not change the amount of work).
pub struct FixedInput {
    obs: Vec<Vec<f32>>,
    prev: Vec<f32>,
    rate: Vec<f32>,
}

impl FixedInput {
    pub fn new(obs_dim: usize, action_dim: usize, history: usize) -> Self {
        FixedInput {
            obs: vec![vec![0.1; obs_dim]; history],
            prev: vec![0.0; action_dim],
            rate: vec![0.0; action_dim],
        }
    }

    pub fn input(&self) -> PolicyInput<'_> {
        PolicyInput {
            obs_history: &self.obs,
            prev_action: &self.prev,
            prev_rate: &self.rate,
        }
    }
}

/// Times `calls` chunks of `policy` after `warmup` untimed ones; returns (median, p99) in us.
pub fn time_policy(
    policy: &mut dyn Policy,
    input: &PolicyInput<'_>,
    warmup: usize,
    calls: usize,
) -> anyhow::Result<(f64, f64)> {
    anyhow::ensure!(calls >= 1, "at least one timed call is needed");
    policy.reset(0);
    for _ in 0..warmup {
        policy.act(input)?;
    }
    let mut times = Vec::with_capacity(calls);
    for _ in 0..calls {
        let start = Instant::now();
        policy.act(input)?;
        times.push(start.elapsed().as_secs_f64() * 1e6);
    }
    Ok((quantile(&times, 0.5), quantile(&times, 0.99)))
}

/// The candle float policies of the default comparison, loaded from `dir` (or synthetic).
fn default_float_policies(cfg: &BenchConfig) -> anyhow::Result<Vec<FloatPolicy>> {
    let kinds = [
        (Role::Student, "student", 1, None),
        (Role::Student, "student", 2, None),
        (Role::Teacher, "teacher", 10, Some(Solver::Heun)),
        (Role::Dp, "dp", 100, None),
        (Role::Dp, "dp", 10, None),
    ];
    let mut out = Vec::new();
    for (role, name, steps, solver) in kinds {
        out.push(if cfg.synthetic {
            fixtures::synthetic_float_policy(&cfg.backbone, 6, role, Some(steps), solver)?
        } else {
            let dir = cfg.dir.join(name);
            FloatPolicy::load(&dir, Some(steps), solver).with_context(|| {
                format!(
                    "loading {} (run `frmd quickstart` first, or pass --synthetic or --policy)",
                    dir.display()
                )
            })?
        });
    }
    Ok(out)
}

/// Policies with their table labels.
type LabelledPolicies = Vec<(String, Box<dyn Policy>)>;

/// The frmd-core policies of one exported student, with that student's own backbone label and
/// input sizes (never those of another policy in the table).
struct CorePolicySet {
    backbone: String,
    input: FixedInput,
    policies: LabelledPolicies,
}

/// The frmd-core int8 and f32 policies for the comparison: the student checkpoint `student`
/// exported as `frmd export` does it, one step and (int8) two steps (or, with `--synthetic`, a
/// random one-step student of `--backbone` exported the same way). Returns the policies, or why
/// there are none.
fn core_policies(cfg: &BenchConfig, student: &Path) -> Result<CorePolicySet, String> {
    match core_policy_rows(cfg, student) {
        Ok(Ok((policies, backbone, dims))) => Ok(CorePolicySet {
            backbone: backbone_label(&backbone),
            input: FixedInput::new(dims.obs_dim, dims.action_dim, dims.history),
            policies,
        }),
        Ok(Err(reason)) => Err(format!("frmd-core policies unavailable: {reason}")),
        Err(e) => Err(format!("frmd-core policies unavailable: {e:#}")),
    }
}

/// The labelled frmd-core policies with their backbone and sizes; the inner error is the
/// synthetic exporter's refusal (a reason to print, not a failure).
type CoreRows = Result<(LabelledPolicies, BackboneConfig, PolicyDims), String>;

fn core_policy_rows(cfg: &BenchConfig, ckpt: &Path) -> anyhow::Result<CoreRows> {
    if cfg.synthetic {
        let dir = std::env::temp_dir().join(format!("frmd-bench-{}", std::process::id()));
        let policies = fixtures::reach_student(&dir, &cfg.backbone, 7);
        let _ = std::fs::remove_dir_all(&dir);
        return Ok(policies?.core.map(|c| {
            let dims = c.int8.dims();
            let mut rows = one_step_rows(c.int8, c.core_f32);
            rows.push(("frmd-core int16-act 1-step".to_string(), Box::new(c.int16)));
            (rows, cfg.backbone.clone(), dims)
        }));
    }
    let export = |steps, activations: &str| {
        let config = ExportConfig {
            steps,
            activations: Some(activations.to_string()),
            ..ExportConfig::for_checkpoint(ckpt)
        };
        export_student(&config, false).with_context(|| {
            format!(
                "exporting {} with {steps} step(s), {activations} activations",
                ckpt.display()
            )
        })
    };
    let student = export(1, "int8")?;
    let backbone = student.meta().model.backbone.clone();
    let blob = student.blob().to_vec();
    let int8 = Int8Policy::from_blob(&blob, "int8")?;
    let dims = int8.dims();
    let mut rows = one_step_rows(int8, Int8Policy::f32_twin(&blob, student, "core-f32")?);
    let two_step = Int8Policy::from_blob(export(2, "int8")?.blob(), "int8-2")?;
    rows.push(("frmd-core int8 2-step".to_string(), Box::new(two_step)));
    let int16 = Int8Policy::from_blob(export(1, "int16")?.blob(), "int16")?;
    rows.push(("frmd-core int16-act 1-step".to_string(), Box::new(int16)));
    Ok(Ok((rows, backbone, dims)))
}

/// The one-step int8 policy and its f32 twin with their table labels.
fn one_step_rows(int8: Int8Policy, f32_twin: Int8Policy) -> LabelledPolicies {
    vec![
        ("frmd-core int8 1-step".to_string(), Box::new(int8)),
        ("frmd-core f32 1-step".to_string(), Box::new(f32_twin)),
    ]
}

/// Runs the whole comparison and returns its rows (reference row first when present) plus a
/// note about what is missing.
pub fn bench_rows(cfg: &BenchConfig) -> anyhow::Result<(Vec<BenchRow>, Option<String>)> {
    let floats = if cfg.policies.is_empty() {
        default_float_policies(cfg)?
    } else {
        let mut v = Vec::new();
        for spec in &cfg.policies {
            v.push(
                FloatPolicy::load(&spec.dir, spec.steps, spec.solver)
                    .with_context(|| format!("loading {}", spec.dir.display()))?,
            );
        }
        v
    };
    // The frmd-core rows export the first student among --policy, else the one in --dir.
    let student = cfg
        .policies
        .iter()
        .zip(&floats)
        .find(|(_, policy)| matches!(policy.sampler(), Sampler::Student { .. }))
        .map_or_else(|| cfg.dir.join("student"), |(spec, _)| spec.dir.clone());
    let (core, note) = match core_policies(cfg, &student) {
        Ok(set) => (Some(set), None),
        Err(reason) => (None, Some(reason)),
    };
    let mut rows = Vec::new();
    floats.first().context("no policy to time")?;
    let (backbone, fixed, core) = match core {
        Some(set) => (set.backbone, set.input, set.policies),
        None => (String::new(), FixedInput::new(1, 1, 1), Vec::new()),
    };
    for (label, mut policy) in core {
        let label = if cfg.policies.is_empty() || cfg.synthetic {
            label
        } else {
            format!("{label} ({})", student.display())
        };
        let (median_us, p99_us) =
            time_policy(policy.as_mut(), &fixed.input(), cfg.warmup, cfg.calls)?;
        rows.push(BenchRow {
            label: label.clone(),
            backbone: backbone.clone(),
            median_us,
            p99_us,
            calls: cfg.calls,
        });
        for (level, median_us, p99_us) in time_kernel_levels(policy.as_mut(), &fixed.input(), cfg)?
        {
            rows.push(BenchRow {
                label: format!("{label} {level}"),
                backbone: backbone.clone(),
                median_us,
                p99_us,
                calls: cfg.calls,
            });
        }
    }
    for mut policy in floats {
        let (o, a, h) = policy.input_sizes();
        let fixed = FixedInput::new(o, a, h);
        let (median_us, p99_us) = time_policy(&mut policy, &fixed.input(), cfg.warmup, cfg.calls)?;
        rows.push(BenchRow {
            label: format!("candle {}", policy.name()),
            backbone: backbone_label(&policy.config().backbone),
            median_us,
            p99_us,
            calls: cfg.calls,
        });
    }
    Ok((rows, note))
}

/// On x86-64 CPUs where frmd-core's int8 kernels use AVX2 (and AVX-VNNI or AVX-512 VNNI): the
/// same policy timed again with the other kernel levels, which give identical outputs (what CPUs
/// without some of those instructions run): `avx-vnni` (the packed weights with 256-bit
/// instructions, where AVX-512 VNNI runs them by default), `row-major` (the packed kernels
/// switched off: the row-major weights with the VNNI level), `avx2` (no VNNI) and `portable`
/// (SSE2).
#[cfg(target_arch = "x86_64")]
fn time_kernel_levels(
    policy: &mut dyn Policy,
    input: &PolicyInput<'_>,
    cfg: &BenchConfig,
) -> anyhow::Result<Vec<(&'static str, f64, f64)>> {
    use frmd_core::kernels::x86;
    let mut rows = Vec::new();
    let name = policy.name();
    if !(name.contains("int8") || name.contains("int16")) || !x86::avx2_active() {
        return Ok(rows);
    }
    let (avx512, vnni, packed) = (
        x86::avx512_active(),
        x86::avx_vnni_active(),
        x86::packed_active(),
    );
    // (label, AVX-512, AVX-VNNI, packed, AVX2)
    let mut levels = Vec::new();
    if packed && avx512 && vnni {
        levels.push(("avx-vnni", false, true, true, true));
    }
    if packed {
        levels.push(("row-major", avx512, vnni, false, true));
    }
    if avx512 || vnni {
        levels.push(("avx2", false, false, false, true));
    }
    levels.push(("portable", false, false, false, false));
    for (label, wide, dot, pack, avx2) in levels {
        x86::set_avx512_enabled(wide);
        x86::set_avx_vnni_enabled(dot);
        x86::set_packed_enabled(pack);
        x86::set_avx2_enabled(avx2);
        let timed = time_policy(policy, input, cfg.warmup, cfg.calls);
        x86::set_avx2_enabled(true);
        x86::set_avx_vnni_enabled(vnni);
        x86::set_avx512_enabled(avx512);
        x86::set_packed_enabled(packed);
        let (median, p99) = timed?;
        rows.push((label, median, p99));
    }
    Ok(rows)
}

#[cfg(not(target_arch = "x86_64"))]
fn time_kernel_levels(
    _: &mut dyn Policy,
    _: &PolicyInput<'_>,
    _: &BenchConfig,
) -> anyhow::Result<Vec<(&'static str, f64, f64)>> {
    Ok(Vec::new())
}

/// Prints the rows with ratios to the first row.
pub fn print_table(rows: &[BenchRow], warmup: usize, note: Option<&str>) {
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into());
    let Some(reference) = rows.first() else {
        return;
    };
    println!(
        "{:<28} {:<22} {:>11} {:>11} {:>6} {:>9}",
        "policy", "backbone", "median us", "p99 us", "calls", "ratio"
    );
    for row in rows {
        println!(
            "{:<28} {:<22} {:>11.1} {:>11.1} {:>6} {:>8.1}x",
            row.label,
            row.backbone,
            row.median_us,
            row.p99_us,
            row.calls,
            row.median_us / reference.median_us
        );
    }
    println!("batch 1, {warmup} warm-up calls, ratio = median / median of `{}`, RAYON_NUM_THREADS={threads}", reference.label);
    if let Some(note) = note {
        println!("note: {note}");
    }
}

/// Writes the rows as JSON.
pub fn write_json(path: &Path, rows: &[BenchRow], note: Option<&str>) -> anyhow::Result<()> {
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into());
    let value =
        serde_json::json!({ "threads": threads, "batch": 1, "results": rows, "note": note });
    frmd_formats::artifact::write_atomic(path, serde_json::to_string_pretty(&value)?.as_bytes())
}
