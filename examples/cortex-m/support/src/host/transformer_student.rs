//! A transformer-lite student for the firmware's blob images (`transformer-student`,
//! `transformer-student16`): a random checkpoint with the synthetic policy's sizes (2 x 8
//! observations, 2 DoF, horizon 12, 21 ProDMP parameters per DoF), its weights drawn like a
//! trained transformer's (`frmd_test_support::checkpoint::Init::Transformer`), exported by
//! frmd-export with int8 or int16 activations. The same student both ways, so their cost is
//! compared on the same network; the host digest test rebuilds it with the same seeds.

use std::path::Path;

use frmd_export::{Activations, ExportOptions, ExportedStudent};
use frmd_formats::calibration;
use frmd_formats::checkpoint::{BackboneConfig, HeadConfig, ModelConfig, Role, CALIBRATION_FILE};
use frmd_test_support::checkpoint::{calibration_rows, unit_normalization, write_checkpoint, Init};

use crate::shape::{CONTROL_DT, DOF, HORIZON, PARAMS, POLICY_HISTORY, POLICY_OBS_DIM};

/// Seed of the checkpoint's weights.
pub const WEIGHT_SEED: u64 = 0x5453_5455_4445_4e54;
/// Calibration rows (and their seeds).
const CALIBRATION_ROWS: usize = 32;

/// The student's model configuration.
pub fn model() -> ModelConfig {
    ModelConfig {
        obs_dim: POLICY_OBS_DIM,
        history: POLICY_HISTORY,
        action_dim: DOF,
        horizon: HORIZON,
        control_dt: CONTROL_DT,
        embed_dim: 16,
        backbone: BackboneConfig::parse("transformer-lite").expect("a known backbone"),
        head: HeadConfig::prodmp(PARAMS - 1),
    }
}

/// Writes the checkpoint (`frmd.json`, `model.safetensors`, `calibration.safetensors`) into
/// `dir`, which must exist.
pub fn write(dir: &Path) {
    let model = model();
    let norm = unit_normalization(POLICY_OBS_DIM, DOF);
    write_checkpoint(
        dir,
        Role::Student,
        &model,
        norm,
        WEIGHT_SEED,
        Init::Transformer,
    );
    calibration::write(
        &dir.join(CALIBRATION_FILE),
        &calibration_rows(&model, CALIBRATION_ROWS, 5, 6),
    )
    .unwrap_or_else(|error| panic!("writing {}: {error:#}", dir.display()));
}

/// The checkpoint in `dir` ([`write`]) exported as `frmd export --activations A` does.
pub fn export(dir: &Path, activations: Activations) -> ExportedStudent {
    let options = ExportOptions {
        activations: Some(activations),
        ..ExportOptions::default()
    };
    frmd_export::export(dir, &options, None).unwrap_or_else(|error| {
        panic!(
            "exporting the transformer student {} failed: {error:#}",
            dir.display()
        )
    })
}
