//! The checked-in trained student (`examples/cortex-m/policy/reach/`) exported exactly as the
//! firmware's build.rs exports it, and the aligned blob storage the tests load its blob form from.

use std::path::{Path, PathBuf};

use frmd_export::export::{export_checkpoint, ExportOptions};
use frmd_export::QuantizedPolicy;

use crate::shape::{DOF, HORIZON, PARAMS, STUDENT_HISTORY, STUDENT_OBS_DIM};

/// The student's checkpoint directory (`model.safetensors`, `frmd.json`,
/// `calibration.safetensors`).
pub fn student_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../policy/reach")
}

/// The student exported as `frmd export` does by default (one step, min/max ranges over its
/// calibration file, balanced inputs): what the `policy` images bake. Panics with the exporter's
/// message if the checkpoint cannot be exported or its shape disagrees with [`crate::shape`]
/// (build script and test helper).
pub fn student() -> QuantizedPolicy {
    let dir = student_dir();
    let exported =
        export_checkpoint(&dir, ExportOptions::default(), None).unwrap_or_else(|error| {
            panic!("exporting the student {} failed: {error:#}", dir.display())
        });
    let policy = exported.policy;
    let shape = (
        policy.history,
        policy.obs_dim,
        policy.action_dim,
        policy.horizon,
        policy.params_per_dof,
    );
    let expected = (STUDENT_HISTORY, STUDENT_OBS_DIM, DOF, HORIZON, PARAMS);
    assert_eq!(
        shape,
        expected,
        "{}: (history, obs_dim, dof, horizon, params) disagree with shape.rs",
        dir.display()
    );
    policy
}

/// A blob copied into 16-byte aligned storage, as `frmd_core::blob` loaders require.
pub struct AlignedBlob {
    words: Vec<u128>,
    len: usize,
}

impl AlignedBlob {
    pub fn new(blob: &[u8]) -> Self {
        let mut words = vec![0_u128; blob.len().div_ceil(16)];
        bytemuck::cast_slice_mut::<u128, u8>(&mut words)[..blob.len()].copy_from_slice(blob);
        Self {
            words,
            len: blob.len(),
        }
    }

    /// The blob of `policy` (`frmd_export::blob::write`); panics if the policy cannot be written.
    pub fn of(policy: &QuantizedPolicy) -> Self {
        Self::new(&frmd_export::blob::write(policy).expect("write the blob"))
    }

    pub fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u128, u8>(&self.words)[..self.len]
    }
}
