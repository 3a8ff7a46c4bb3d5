//! End to end: collect a small `reach` dataset, train a tiny teacher, distill a tiny student
//! (through the `frmd train` code paths, which also write calibration.safetensors), export it
//! (`frmd export`), load the blob with frmd-core and run the bit-accuracy harness.
use frmd_core::blob::AlignedBlob;

mod support;
use support::{assert_tiny_dims, equiv_within_bounds, row, train_tiny, Tiny};

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
    // The exporter refuses the teacher, naming the reason.
    let err = frmd_export::export(&run.teacher, &Default::default(), None).unwrap_err();
    assert!(
        format!("{err:#}").contains("a teacher checkpoint"),
        "{err:#}"
    );

    let blob = AlignedBlob::new(&run.export_student());
    for file in ["policy.rs", "weights.bin", "export.json"] {
        assert!(run.baked.join(file).exists(), "{file}");
    }

    // frmd-core loads the blob zero-copy with the shapes of this model, and only with those; the
    // default export of an MLP has int16 activations, which the int8 loader names.
    assert_eq!(
        frmd_core::blob::LoadedMlp::load(blob.bytes()).err(),
        Some(frmd_core::blob::BlobError::ActivationBits { found: 16 })
    );
    let loaded = frmd_core::blob::LoadedMlp16::load(blob.bytes()).unwrap();
    assert_tiny_dims(|dims| loaded.check_dims(dims));
    assert_eq!(loaded.steps().len(), 1);
    // The tiny run trains with the boundary skip: the step carries the consistency c_skip and
    // c_out at sigma_max (a direct-output student would have 0 and 1).
    let sigma = frmd_core::sigma::SigmaConfig::default();
    assert_eq!(
        loaded.steps()[0].c_skip,
        sigma.c_skip(sigma.sigma_max).unwrap() as f32
    );
    assert_eq!(
        loaded.steps()[0].c_out,
        sigma.c_out(sigma.sigma_max).unwrap() as f32
    );

    let report = equiv_within_bounds(&run.student, &run.baked, 10, 64);
    assert_eq!(
        row(&report, "success-rate difference core f32"),
        0.0,
        "runtime f32 policy must reproduce candle in closed loop"
    );
    assert_eq!(row(&report, "int16-activation network accumulator"), 0.0);
    let _ = std::fs::remove_dir_all(&run.dir);
}
