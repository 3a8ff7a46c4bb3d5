//! The checked-in trained student (`examples/cortex-m/policy/reach/`) exported exactly as the
//! firmware's build.rs exports it.

use std::path::{Path, PathBuf};

use frmd_export::mlp::QuantizedMlp;
use frmd_export::{Activations, ExportOptions, ExportedStudent};

use crate::shape::{DOF, HORIZON, PARAMS, STUDENT_HISTORY, STUDENT_OBS_DIM};

/// The student's checkpoint directory (`model.safetensors`, `frmd.json`,
/// `calibration.safetensors`).
pub fn student_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../policy/reach")
}

/// The student exported as `frmd export` does by default (one step, min/max ranges over its
/// calibration file, balanced inputs, the 16-bit input) but with int8 activations: what the
/// `policy` images bake (the `policy16` images bake the int16 default, [`student_export_as`]).
/// Panics with the exporter's message if the checkpoint cannot be exported (build script and
/// test helper).
pub fn student_export() -> ExportedStudent {
    student_export_as(Activations::Int8)
}

/// [`student_export`] with the hidden activations in `activations` (the `policy16` image bakes
/// it with int16 activations).
pub fn student_export_as(activations: Activations) -> ExportedStudent {
    let dir = student_dir();
    let options = ExportOptions {
        activations: Some(activations),
        ..ExportOptions::default()
    };
    frmd_export::export(&dir, &options, None)
        .unwrap_or_else(|error| panic!("exporting the student {} failed: {error:#}", dir.display()))
}

/// The int8 MLP of [`student_export`]; panics if its shape disagrees with [`crate::shape`] (the
/// firmware images are built for that shape).
pub fn student() -> QuantizedMlp {
    let exported = student_export();
    let policy = exported
        .mlp()
        .expect("the checked-in student is an MLP")
        .policy
        .clone();
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
        student_dir().display()
    );
    policy
}
