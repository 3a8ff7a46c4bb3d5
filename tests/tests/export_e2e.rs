//! End to end: collect a small `reach` dataset, train a tiny teacher, distill a tiny student
//! (through the `frmd train` code paths, which also write calibration.safetensors), export it
//! (`frmd export`), load the blob with frmd-core and run the bit-accuracy harness.
use frmd_core::policy::PolicyDims;
use frmd_host::export::BAKED_BLOB_FILE;
use frmd_test_support::AlignedBlob;

mod support;
use support::{equiv_within_bounds, row, train_tiny, Tiny, TinyRun};

/// The sizes of the tiny runs: history 2, `reach` (6 observations, 2 DoF), horizon 8, 6 basis
/// functions plus the goal.
const TINY_DIMS: PolicyDims = PolicyDims { history: 2, obs_dim: 6, action_dim: 2, horizon: 8, params_per_dof: 7 };

#[test]
fn tiny_student_exports_and_meets_the_harness_bounds() {
    let run = train_tiny(
        "frmd-export-e2e",
        &Tiny {
            backbone: "mlp:32,32:silu",
            seed: 3,
            batch: 32,
            lr: 3e-3,
            warmup: 20,
            teacher_steps: 300,
            loss_weight: "edm",
            student_steps: 150,
        },
    );
    let TinyRun {
        dir,
        teacher,
        student,
        baked,
    } = &run;

    // The exporter refuses the teacher, naming the reason.
    let err =
        frmd_export::export::export_checkpoint(teacher, Default::default(), None).unwrap_err();
    assert!(format!("{err:#}").contains("Teacher"), "{err:#}");

    run.export(student).unwrap();
    assert_eq!(
        std::fs::read(dir.join("student.blob")).unwrap(),
        std::fs::read(baked.join(BAKED_BLOB_FILE)).unwrap()
    );
    for file in ["policy.rs", "weights.bin", "export.json"] {
        assert!(baked.join(file).exists(), "{file}");
    }

    // frmd-core loads the blob zero-copy with the shapes of this model.
    let blob = AlignedBlob::new(&std::fs::read(baked.join(BAKED_BLOB_FILE)).unwrap());
    let loaded = frmd_core::blob::LoadedMlp::load(blob.bytes()).unwrap();
    assert_eq!(loaded.check_dims(&TINY_DIMS), Ok(()));
    assert_eq!(loaded.steps().len(), 1);
    // The tiny run trains with the boundary skip: the step carries the consistency c_skip and
    // c_out at sigma_max (a direct-output student would have 0 and 1).
    let sigma = frmd_core::sigma::SigmaConfig::default();
    assert_eq!(loaded.steps()[0].c_skip, sigma.c_skip(sigma.sigma_max).unwrap() as f32);
    assert_eq!(loaded.steps()[0].c_out, sigma.c_out(sigma.sigma_max).unwrap() as f32);
    assert!(matches!(
        loaded.check_dims(&PolicyDims { horizon: 12, params_per_dof: 21, ..TINY_DIMS }),
        Err(frmd_core::blob::BlobError::DimensionMismatch(_))
    ));

    let report = equiv_within_bounds(student, baked, 10, 64);
    assert_eq!(
        row(&report, "success-rate difference core f32"),
        0.0,
        "runtime f32 policy must reproduce candle in closed loop"
    );
    assert_eq!(row(&report, "int8 network accumulator"), 0.0);
    let _ = std::fs::remove_dir_all(dir);
}
