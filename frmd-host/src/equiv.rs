//! The bit-accuracy harness of docs/design.md section 6 (`frmd equiv`):
//! - (a) frmd-core's f32 path (the exporter's folded network on frmd-core's f32 kernels) vs the
//!   candle float student, same conditions and noise: max abs error, normalized units;
//! - (b) frmd-core's int8 policy (loaded from the baked blob) vs the candle float student: max and
//!   mean abs error of the chunk in action units over many inputs, and the success-rate
//!   difference over closed-loop episodes on the checkpoint's task (same episode seeds, same
//!   noise generator);
//! - (c) x86-64 vs Cortex-M bytes: run by `examples/cortex-m/run-qemu.sh` (reported as such);
//! - (d) frmd-core's int8 kernels vs the independent wide-integer model
//!   (`frmd_export::reference`): requantization on edges, ties and random inputs, and the
//!   exported network's accumulators on the (a) inputs plus saturating/zero-point edge inputs.
//!
//! Also checked: the baked blob is reproduced bit for bit by re-exporting the checkpoint. Every
//! backbone gets the same rows: the re-export ([`frmd_export::ExportedStudent`]) provides the
//! f32 path, the f32 network of the twin policy and check (d) for its backbone.
use crate::checkpoint::{self, CheckpointMeta, Role};
use crate::diffusion::samplers::{gaussian, sample_consistency};
use crate::eval::{run_episodes, EvalConfig};
use crate::export::{export_student, ExportConfig};
use crate::limits::{self, OptionError};
use crate::models::Condition;
use crate::policy::float::FloatPolicy;
use crate::policy::int8::Int8Policy;
use crate::tasks::{Policy, PolicyInput};
use anyhow::Context;
use candle_core::Device;
use frmd_core::rng::Rng;
use frmd_export::bake::BLOB_FILE;
use frmd_export::reference::KernelCheck;
use frmd_export::ExportedStudent;
use serde::Serialize;
use std::path::PathBuf;

/// Harness settings and bounds.
#[derive(Clone, Debug)]
pub struct EquivConfig {
    /// The student checkpoint.
    pub ckpt: PathBuf,
    /// Its baked module directory (`frmd export --out`).
    pub baked: PathBuf,
    /// Closed-loop episodes per method (0 skips the success-rate check).
    pub episodes: usize,
    /// Open-loop conditions for (a), (b) and (d) (taken from the calibration rows, fresh noise).
    pub inputs: usize,
    /// Random requantization cases of (d).
    pub random_requant: u64,
    /// Calibration data override (else what `export.json` names, else the checkpoint's file).
    pub data: Option<PathBuf>,
    /// (a) bound, normalized units.
    pub max_f32_error: f64,
    /// (b) bound of the max abs error as a fraction of the mean action range.
    pub max_int8_error_frac: f64,
    /// (b) bound of the mean abs error as a fraction of the mean action range.
    pub mean_int8_error_frac: f64,
    /// (b) success-rate difference bound, percentage points.
    pub max_success_diff_points: f64,
}

impl Default for EquivConfig {
    /// The bounds of docs/design.md section 6 and the effort of `frmd equiv`; no paths named.
    fn default() -> Self {
        EquivConfig {
            ckpt: PathBuf::new(),
            baked: PathBuf::new(),
            episodes: 100,
            inputs: 200,
            random_requant: 1_000_000,
            data: None,
            max_f32_error: 1e-3,
            max_int8_error_frac: 0.10,
            mean_int8_error_frac: 0.02,
            max_success_diff_points: 5.0,
        }
    }
}

impl EquivConfig {
    /// The default checks of the student in `ckpt` against its export in `baked`.
    pub fn new(ckpt: PathBuf, baked: PathBuf) -> Self {
        EquivConfig {
            ckpt,
            baked,
            ..EquivConfig::default()
        }
    }

    /// Counts and bounds before any work; checks (a) and (b) need at least one input (with none
    /// they would pass on nothing).
    pub fn validate(&self) -> Result<(), OptionError> {
        limits::count("episodes", self.episodes, 0, limits::MAX_EPISODES)?;
        if self.inputs == 0 {
            return Err(limits::range(
                "inputs",
                0,
                format!(
                    "1 to {} (checks (a) and (b) run on these inputs; 0 would check nothing)",
                    limits::MAX_CHECKS
                ),
            ));
        }
        limits::count("inputs", self.inputs, 1, limits::MAX_CHECKS)?;
        if self.random_requant > 1_000_000_000 {
            return Err(limits::range(
                "random-requant",
                self.random_requant,
                "0 to 1000000000",
            ));
        }
        limits::positive("max-f32-error", self.max_f32_error)?;
        limits::positive("max-int8-error-frac", self.max_int8_error_frac)?;
        limits::positive("mean-int8-error-frac", self.mean_int8_error_frac)?;
        limits::non_negative("max-success-diff", self.max_success_diff_points)
    }
}

/// One line of the report.
#[derive(Clone, Debug, Serialize)]
pub struct EquivRow {
    /// Which check of docs/design.md section 6 (`a`..`d`, `export`).
    pub check: String,
    /// What was measured.
    pub metric: String,
    /// The measurement.
    pub value: f64,
    /// `value <= bound` passes; `None`: informational.
    pub bound: Option<f64>,
    /// Whether the row passed (`None`: informational).
    pub pass: Option<bool>,
    /// Context: inputs, episodes, first mismatch.
    pub note: String,
}

/// The harness's rows.
#[derive(Clone, Debug, Serialize)]
pub struct EquivReport {
    /// One row per measurement.
    pub rows: Vec<EquivRow>,
    /// Every bounded row passed.
    pub passed: bool,
}

fn row(check: &str, metric: &str, value: f64, bound: Option<f64>, note: String) -> EquivRow {
    EquivRow {
        check: check.into(),
        metric: metric.into(),
        value,
        bound,
        pass: bound.map(|b| value <= b),
        note,
    }
}

/// Everything the checks share: the candle student, the re-export (with its calibration rows)
/// and the baked blob.
struct Setup {
    meta: CheckpointMeta,
    net: crate::models::OwnedNetwork,
    norm: crate::data::Normalization,
    student: ExportedStudent,
    blob: Vec<u8>,
    /// The exported activations (`int8`, `int16`), the label of the quantized policy's rows.
    label: String,
}

fn setup(cfg: &EquivConfig) -> anyhow::Result<Setup> {
    cfg.validate()?;
    let (meta, net): (CheckpointMeta, _) = checkpoint::load(&cfg.ckpt)?;
    if meta.role != Role::Student {
        anyhow::bail!("--ckpt {}: this is a {}, not a student (equiv checks an exported student against its checkpoint)", cfg.ckpt.display(), meta.role);
    }
    let mut info = ExportConfig::read(&cfg.baked)?;
    info.checkpoint = cfg.ckpt.display().to_string();
    if let Some(data) = &cfg.data {
        info.calibration_data = Some(data.display().to_string());
    }
    let blob_path = cfg.baked.join(BLOB_FILE);
    let blob =
        std::fs::read(&blob_path).with_context(|| format!("reading {}", blob_path.display()))?;
    let norm = meta
        .normalization
        .clone()
        .context("checkpoint has no normalization")?;
    Ok(Setup {
        label: info.activations.clone().unwrap_or_else(|| "int8".into()),
        student: export_student(&info, false)?,
        meta,
        net,
        norm,
        blob,
    })
}

/// Checks (a) and (b) open loop: the candle student, frmd-core's f32 path (normalized units) and
/// the int8 policy on the first `cfg.inputs` calibration rows with fresh noise. Returns the rows
/// and the f32 path's step-0 model inputs (for check (d)).
fn open_loop(
    cfg: &EquivConfig,
    s: &Setup,
    int8: &mut Int8Policy,
) -> anyhow::Result<(Vec<EquivRow>, Vec<Vec<f32>>)> {
    let steps = s.student.steps();
    let model = &s.meta.model;
    let sigma = s.meta.sigma;
    let (k, traj, obs_w) = (
        model.action_dim,
        model.traj_dim(),
        model.history * model.obs_dim,
    );
    let norm = &s.norm;
    let set = s.student.calibration();
    let mut network_inputs = Vec::new();
    let rate_scale = norm.action.scale();
    let range: f64 = norm
        .action
        .min
        .iter()
        .zip(&norm.action.max)
        .map(|(lo, hi)| f64::from(hi - lo))
        .sum::<f64>()
        / k as f64;
    let (mut max_a, mut max_b, mut sum_b, mut count_b) = (0f64, 0f64, 0f64, 0usize);
    let rows_used = cfg.inputs.min(set.rows());
    for r in 0..rows_used {
        let cond = &set.cond[r * set.cond_dim..(r + 1) * set.cond_dim];
        let seed = 0xe901_0000 + r as u64;
        let mut noise = vec![0f32; steps * traj];
        Rng::new(seed).fill_gaussian(&mut noise);
        // Candle float student, noise from the same generator and seed.
        let mut rng = Rng::new(seed);
        let z = gaussian(&mut rng, 1, traj, &Device::Cpu)?;
        let condition = Condition::from_slices(
            model,
            &cond[..obs_w],
            &cond[obs_w..obs_w + k],
            &cond[obs_w + k..],
            &Device::Cpu,
        )?;
        let float: Vec<f32> =
            sample_consistency(&s.net.net, &sigma, &condition, &z, steps, &mut rng)?
                .flatten_all()?
                .to_vec1()?;
        let core = s.student.sample_f32(cond, &noise, |step, input| {
            if step == 0 {
                network_inputs.push(input.to_vec());
            }
        })?;
        max_a = float
            .iter()
            .zip(&core)
            .map(|(a, b)| f64::from((a - b).abs()))
            .fold(max_a, f64::max);
        // frmd-core int8 policy on raw inputs.
        let history: Vec<Vec<f32>> = cond[..obs_w]
            .chunks_exact(model.obs_dim)
            .map(|o| {
                let mut raw = o.to_vec();
                norm.obs.denormalize(&mut raw);
                raw
            })
            .collect();
        let mut prev = cond[obs_w..obs_w + k].to_vec();
        norm.action.denormalize(&mut prev);
        let rate: Vec<f32> = cond[obs_w + k..]
            .iter()
            .zip(&rate_scale)
            .map(|(v, s)| if *s > 0.0 { v / s } else { 0.0 })
            .collect();
        let chunk = int8.run_with_noise(
            &PolicyInput {
                obs_history: &history,
                prev_action: &prev,
                prev_rate: &rate,
            },
            &noise,
        )?;
        let mut float_raw = float.clone();
        norm.action.denormalize(&mut float_raw);
        for (a, b) in chunk.iter().flatten().zip(&float_raw) {
            let e = f64::from((a - b).abs());
            max_b = max_b.max(e);
            sum_b += e;
            count_b += 1;
        }
    }
    let mean_b = sum_b / count_b.max(1) as f64;
    let rows = vec![
        row(
            "a",
            "core f32 vs candle float: max abs error (normalized)",
            max_a,
            Some(cfg.max_f32_error),
            format!("{rows_used} inputs, {steps} step(s)"),
        ),
        row(
            "b",
            &format!(
                "core {} vs candle float: max abs error (action units)",
                s.label
            ),
            max_b,
            Some(cfg.max_int8_error_frac * range),
            format!(
                "bound {:.0} % of mean action range {range:.4}",
                100.0 * cfg.max_int8_error_frac
            ),
        ),
        row(
            "b",
            &format!(
                "core {} vs candle float: mean abs error (action units)",
                s.label
            ),
            mean_b,
            Some(cfg.mean_int8_error_frac * range),
            format!(
                "bound {:.0} % of mean action range",
                100.0 * cfg.mean_int8_error_frac
            ),
        ),
    ];
    Ok((rows, network_inputs))
}

/// Success rates of the candle student, the int8 policy and the runtime policy with frmd-core's
/// f32 network (`twin`) on the checkpoint's task.
fn closed_loop(
    cfg: &EquivConfig,
    s: &Setup,
    int8: &mut Int8Policy,
    twin: &mut Int8Policy,
) -> anyhow::Result<Vec<EquivRow>> {
    let steps = s.student.steps();
    let task = s.meta.dataset.task.clone();
    let eval = EvalConfig {
        episodes: cfg.episodes,
        history: s.meta.model.history,
        ..EvalConfig::default()
    };
    let mut float = FloatPolicy::load(&cfg.ckpt, Some(steps), None)?;
    let f = run_episodes(&task, &mut float, &eval)?;
    int8.reset(0);
    let i = run_episodes(&task, int8, &eval)?;
    let t = run_episodes(&task, twin, &eval)?;
    let diff = 100.0 * (f.success_rate - i.success_rate).abs();
    Ok(vec![
        row("a", "success-rate difference core f32 vs candle (points)", 100.0 * (f.success_rate - t.success_rate).abs(), Some(cfg.max_success_diff_points), format!(
            "{task}, {} episodes: candle {:.1} %, core f32 (runtime policy, f32 network) {:.1} %", cfg.episodes, 100.0 * f.success_rate, 100.0 * t.success_rate
        )),
        row("b", "success-rate difference (points)", diff, Some(cfg.max_success_diff_points), format!(
            "{task}, {} episodes: float {:.1} %, {label} {:.1} %; latency median float {:.1} us, {label} {:.1} us",
            cfg.episodes, 100.0 * f.success_rate, 100.0 * i.success_rate, f.latency_us_median, i.latency_us_median, label = s.label
        )),
    ])
}

fn blob_row(blob: &[u8], rebuilt: &[u8], cfg: &EquivConfig) -> EquivRow {
    let path = cfg.baked.join(BLOB_FILE);
    row(
        "export",
        "baked blob differs from a re-export (0 = identical)",
        f64::from(u8::from(rebuilt != blob)),
        Some(0.0),
        path.display().to_string(),
    )
}

fn qemu_row() -> EquivRow {
    EquivRow {
        check: "c".into(),
        metric: "x86-64 vs Cortex-M bytes".into(),
        value: f64::NAN,
        bound: None,
        pass: None,
        note: "not run here: see examples/cortex-m/run-qemu.sh (digest line)".into(),
    }
}

/// A row of check (d): mismatches of `check` (its name is the metric), which must be 0.
fn kernel_row(check: &KernelCheck) -> EquivRow {
    row(
        "d",
        &check.name,
        check.mismatches as f64,
        Some(0.0),
        format!(
            "{} cases{}",
            check.cases,
            check
                .first_mismatch
                .as_ref()
                .map(|m| format!("; first: {m}"))
                .unwrap_or_default()
        ),
    )
}

fn report(rows: Vec<EquivRow>) -> EquivReport {
    let passed = rows.iter().all(|r| r.pass != Some(false));
    EquivReport { rows, passed }
}

/// Runs every check.
pub fn run(cfg: &EquivConfig) -> anyhow::Result<EquivReport> {
    let s = setup(cfg)?;
    let mut rows = vec![blob_row(&s.blob, s.student.blob(), cfg)];
    let mut int8 = Int8Policy::from_blob(&s.blob, &s.label)?;
    let (open, network_inputs) = open_loop(cfg, &s, &mut int8)?;
    rows.extend(open);
    if cfg.episodes > 0 {
        let mut twin = Int8Policy::f32_twin(&s.blob, s.student.clone(), "core-f32")?;
        rows.extend(closed_loop(cfg, &s, &mut int8, &mut twin)?);
    }
    rows.push(qemu_row());
    let mut requant = frmd_export::reference::check_requantization(cfg.random_requant, 0x0dd5);
    requant.name = "requantization mismatches vs i128 model".into();
    rows.push(kernel_row(&requant));
    rows.push(kernel_row(&s.student.check_kernels(&network_inputs)?));
    Ok(report(rows))
}

/// The report as a table.
pub fn print(report: &EquivReport) {
    println!(
        "{:<6} {:<58} {:>12} {:>12} {:<5}  note",
        "check", "metric", "value", "bound", ""
    );
    for r in &report.rows {
        let status = match r.pass {
            Some(true) => "PASS",
            Some(false) => "FAIL",
            None => "-",
        };
        let bound = r
            .bound
            .map(|b| format!("{b:.4e}"))
            .unwrap_or_else(|| "-".into());
        println!(
            "{:<6} {:<58} {:>12.4e} {:>12} {:<5}  {}",
            r.check, r.metric, r.value, bound, status, r.note
        );
    }
    println!("{}", if report.passed { "ALL PASS" } else { "FAIL" });
}
