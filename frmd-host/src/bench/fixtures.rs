//! Randomly initialized models at a task's shape for the chunk benchmarks (`benches/`), the
//! instruction counts (`examples/chunk_icount.rs`) and `frmd bench --synthetic`: timing does not
//! depend on the weight values. Sizes follow the training recipe ([`TrainConfig`]: history,
//! horizon, basis functions, noise embedding) with 2-D actions and identity-range normalization.
//! [`reach_student`] also saves the student with calibration rows and exports it, so the float
//! student, the core f32 twin and the int8 policy run the same model.
use crate::checkpoint::{self, CheckpointMeta, Role, CALIBRATION_FILE};
use crate::data::{Normalization, Normalizer};
use crate::diffusion::samplers::Solver;
use crate::models::{BackboneConfig, HeadConfig, ModelConfig, OwnedNetwork};
use crate::policy::float::{FloatPolicy, Sampler};
use crate::policy::int8::Int8Policy;
use crate::train::recipe::TrainConfig;
use candle_core::Device;
use frmd_core::rng::Rng;
use frmd_core::sigma::SigmaConfig;
use frmd_export::{Activations, ExportOptions};
use frmd_formats::calibration::CalibrationSet;
use std::path::Path;

/// Actions of the synthetic models (planar tasks).
const ACTION_DIM: usize = 2;

/// A model of `backbone` for `obs_dim` observations with the recipe's sizes; `role` picks the
/// head (ProDMP for teacher and student, raw for DP).
fn task_sized_model(
    obs_dim: usize,
    control_dt: f64,
    backbone: &BackboneConfig,
    role: Role,
) -> ModelConfig {
    let recipe = TrainConfig::default();
    let head = match role {
        Role::Dp => HeadConfig::Raw,
        Role::Teacher | Role::Student => HeadConfig::prodmp(recipe.num_basis),
    };
    ModelConfig {
        obs_dim,
        history: recipe.history,
        action_dim: ACTION_DIM,
        horizon: recipe.horizon,
        control_dt,
        embed_dim: recipe.embed_dim,
        backbone: backbone.clone(),
        head,
    }
}

/// Normalization mapping [-1, 1] to itself.
fn unit_normalization(obs_dim: usize) -> Normalization {
    let unit = |dim: usize| Normalizer {
        min: vec![-1.0; dim],
        max: vec![1.0; dim],
    };
    Normalization {
        obs: unit(obs_dim),
        action: unit(ACTION_DIM),
    }
}

/// A float policy of `role` on a randomly initialized network of `backbone` with `obs_dim`
/// observations (for latency only).
pub fn synthetic_float_policy(
    backbone: &BackboneConfig,
    obs_dim: usize,
    role: Role,
    steps: Option<usize>,
    solver: Option<Solver>,
) -> anyhow::Result<FloatPolicy> {
    let cfg = task_sized_model(obs_dim, 0.1, backbone, role);
    let net = OwnedNetwork::new_seeded(&cfg, 7, &Device::Cpu)?;
    FloatPolicy::new(
        net,
        unit_normalization(obs_dim),
        SigmaConfig::default(),
        Sampler::for_role(role, steps, solver)?,
    )
}

/// The three policies of one model.
pub struct BenchPolicies {
    pub float: FloatPolicy,
    /// frmd-core policies; `None` (with the exporter's reason) for backbones it cannot export.
    pub core: Result<CorePolicies, String>,
}

/// frmd-core's int8 policy, its f32 twin and the int16-activation export.
pub struct CorePolicies {
    pub core_f32: Int8Policy,
    pub int8: Int8Policy,
    /// The same student exported with int16 activations.
    pub int16: Int8Policy,
    /// The blobs of `int8` and `int16` (for the stage breakdown, [`super::stages`]).
    pub int8_blob: Vec<u8>,
    pub int16_blob: Vec<u8>,
    /// Flash bytes (weights + tables) of the int8 policy.
    pub flash_bytes: usize,
}

/// Builds a random student of `backbone` at the reach shape (O 6), writes it under `dir`,
/// exports it and loads all three policies.
pub fn reach_student(
    dir: &Path,
    backbone: &BackboneConfig,
    seed: u64,
) -> anyhow::Result<BenchPolicies> {
    let model = task_sized_model(6, 0.05, backbone, Role::Student);
    let net = OwnedNetwork::new_seeded(&model, seed, &Device::Cpu)?;
    let sigma = SigmaConfig::default();
    let mut meta = CheckpointMeta::describe(Role::Student, &model, sigma);
    let norm = unit_normalization(model.obs_dim);
    meta.normalization = Some(norm.clone());
    checkpoint::save(dir, &meta, &net)?;
    let mut rng = Rng::new(seed);
    let cond_dim = model.cond_dim();
    let cond: Vec<f32> = (0..64 * cond_dim)
        .map(|_| (0.5 * rng.gaussian()).clamp(-1.0, 1.0))
        .collect();
    frmd_formats::calibration::write(
        &dir.join(CALIBRATION_FILE),
        &CalibrationSet {
            cond_dim,
            cond,
            seed,
        },
    )?;
    let int16 = ExportOptions {
        activations: Some(Activations::Int16),
        ..ExportOptions::default()
    };
    let int8 = ExportOptions {
        activations: Some(Activations::Int8),
        ..ExportOptions::default()
    };
    let core = match frmd_export::export(dir, &int8, None) {
        Ok(student) => {
            let blob = student.blob().to_vec();
            let int16_blob = frmd_export::export(dir, &int16, None)?.blob().to_vec();
            Ok(CorePolicies {
                flash_bytes: student.memory().flash_bytes(),
                int8: Int8Policy::from_blob(&blob, "int8")?,
                int8_blob: blob.clone(),
                int16: Int8Policy::from_blob(&int16_blob, "int16")?,
                int16_blob,
                core_f32: Int8Policy::f32_twin(&blob, student, "core-f32")?,
            })
        }
        Err(e) => Err(format!("{e:#}")),
    };
    Ok(BenchPolicies {
        float: FloatPolicy::new(net, norm, sigma, Sampler::Student { steps: 1 })?,
        core,
    })
}

/// A fixed raw input at the reach shape.
pub fn reach_input() -> (Vec<Vec<f32>>, Vec<f32>, Vec<f32>) {
    (
        vec![vec![0.1, -0.2, 0.3, 0.0, 0.5, -0.4]; 2],
        vec![0.2, -0.1],
        vec![0.5, 0.3],
    )
}
