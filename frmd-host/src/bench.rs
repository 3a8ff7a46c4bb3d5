//! Fixtures for the chunk benchmark (`benches/chunk.rs`) and instruction counts
//! (`examples/chunk_icount.rs`): a student checkpoint with randomly initialized weights at a
//! task's shape (timing does not depend on the weight values), saved with calibration rows and
//! exported, so the float student, the core f32 twin and the int8 policy run the same model.
use crate::checkpoint::{self, CheckpointMeta, Role, CALIBRATION_FILE};
use crate::data::{Normalization, Normalizer};
use crate::models::{BackboneConfig, HeadConfig, ProDmpOutput, ModelConfig, OwnedNetwork};
use crate::policy::float::{FloatPolicy, Sampler};
use crate::policy::int8::Int8Policy;
use candle_core::Device;
use frmd_core::rng::Rng;
use frmd_core::sigma::SigmaConfig;
use frmd_export::calibrate::CalibrationSet;
use frmd_export::export::{export_checkpoint, ExportOptions};
use std::path::Path;

/// The three policies of one model.
pub struct BenchPolicies {
    pub float: FloatPolicy,
    /// frmd-core policies; `None` (with the exporter's reason) for backbones it cannot export.
    pub core: Result<CorePolicies, String>,
}

/// frmd-core's int8 policy and its f32 twin.
pub struct CorePolicies {
    pub core_f32: Int8Policy,
    pub int8: Int8Policy,
    /// Flash bytes (weights + tables) of the int8 policy.
    pub flash_bytes: usize,
}

/// Builds a random student at the reach shape (m 2, O 6, K 2, n 12, 20 basis functions) with
/// `backbone` (e.g. `mlp`), writes it under `dir`, exports it and loads all three policies.
pub fn reach_student(dir: &Path, backbone: &str, seed: u64) -> anyhow::Result<BenchPolicies> {
    let model = ModelConfig {
        obs_dim: 6,
        history: 2,
        action_dim: 2,
        horizon: 12,
        control_dt: 0.05,
        embed_dim: 16,
        backbone: BackboneConfig::parse(backbone)?,
        head: HeadConfig::ProDmp { num_basis: 20, output: ProDmpOutput::Direct },
    };
    let net = OwnedNetwork::new_seeded(&model, seed, &Device::Cpu)?;
    let sigma = SigmaConfig::default();
    let mut meta = CheckpointMeta::describe(Role::Student, &model, sigma);
    let norm = Normalization {
        obs: Normalizer { min: vec![-1.0; 6], max: vec![1.0; 6] },
        action: Normalizer { min: vec![-1.0; 2], max: vec![1.0; 2] },
    };
    meta.normalization = Some(norm.clone());
    checkpoint::save(dir, &meta, &net)?;
    let mut rng = Rng::new(seed);
    let cond_dim = model.cond_dim();
    let cond: Vec<f32> = (0..64 * cond_dim).map(|_| (0.5 * rng.gaussian()).clamp(-1.0, 1.0)).collect();
    frmd_export::calibration_file::write(&dir.join(CALIBRATION_FILE), &CalibrationSet { cond_dim, cond, seed })?;
    let core = match export_checkpoint(dir, ExportOptions::default(), None) {
        Ok(exported) => {
            let blob = frmd_export::blob::write(&exported.policy).map_err(|e| anyhow::anyhow!("blob: {e}"))?;
            Ok(CorePolicies {
                core_f32: Int8Policy::f32_twin(&blob, exported.folded.clone(), "core-f32")?,
                int8: Int8Policy::from_blob(&blob, "int8")?,
                flash_bytes: exported.policy.memory().flash_bytes(),
            })
        }
        Err(e) => Err(format!("{e:#}")),
    };
    Ok(BenchPolicies { float: FloatPolicy::new(net, norm, sigma, Sampler::Student { steps: 1 })?, core })
}

/// A fixed raw input at the reach shape.
pub fn reach_input() -> (Vec<Vec<f32>>, Vec<f32>, Vec<f32>) {
    (vec![vec![0.1, -0.2, 0.3, 0.0, 0.5, -0.4]; 2], vec![0.2, -0.1], vec![0.5, 0.3])
}
