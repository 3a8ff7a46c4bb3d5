//! End to end for transformer-lite: collect a small `reach` dataset, train a briefly trained
//! transformer-lite teacher and student through the `frmd train` code paths, export the student
//! with `frmd export` (the backbone picks the transformer exporter: `FRMT` blob plus generated
//! loader module), load the blob with frmd-core and run the bit-accuracy harness.
use frmd_core::blob::AlignedBlob;

mod support;
use support::{assert_tiny_dims, equiv_within_bounds, row, train_tiny, Tiny};

#[test]
fn tiny_transformer_student_exports_and_meets_the_harness_bounds() {
    let run = train_tiny(
        "frmd-transformer-e2e",
        &Tiny {
            backbone: "transformer-lite",
            seed: 5,
            batch: 16,
            lr: 1e-3,
            warmup: 10,
            teacher_steps: 60,
            loss_weight: "uniform",
            student_steps: 20,
        },
    );
    let (baked, student) = (&run.baked, &run.student);

    // The exporter refuses the teacher, naming the reason.
    let err = run.export(&run.teacher).unwrap_err();
    assert!(
        format!("{err:#}").contains("this is a teacher checkpoint"),
        "{err:#}"
    );

    let blob = run.export_student();
    assert_eq!(&blob[..4], b"FRMT");
    for file in ["policy.rs", "export.json"] {
        assert!(baked.join(file).exists(), "{file}");
    }
    assert!(
        !baked.join("weights.bin").exists(),
        "the MLP weight file is not written for a transformer"
    );
    let module = std::fs::read_to_string(baked.join("policy.rs")).unwrap();
    for line in [
        "pub const HORIZON: usize = 8;",
        "pub const LAYERS: usize = 3;",
        "pub const WIDTH: usize = 128;",
        &format!("pub const BLOB_BYTES: usize = {};", blob.len()),
    ] {
        assert!(module.contains(line), "policy.rs lacks `{line}`");
    }

    // The flash figure counts every section the loader views: the blob adds only its header,
    // descriptor and alignment padding.
    let student_export = frmd_export::export(student, &Default::default(), None).unwrap();
    let exported = student_export.transformer().expect("a transformer export");
    let memory = student_export.memory();
    assert_eq!(
        memory.scratch_bytes,
        exported.model.folded.shape.int8_scratch().ram_bytes()
    );
    assert!(
        memory.flash_bytes() <= blob.len() && blob.len() - memory.flash_bytes() < 4096,
        "flash {} vs blob {}",
        memory.flash_bytes(),
        blob.len()
    );

    // frmd-core loads the blob zero-copy with the shapes of this model, and only with those.
    let aligned = AlignedBlob::new(&blob);
    let bytes = aligned.bytes();
    let loaded = frmd_core::blob::LoadedTransformer::load(bytes).unwrap();
    assert_tiny_dims(|dims| loaded.check_dims(dims));
    assert_eq!(loaded.steps().len(), 1);
    assert_eq!(
        (
            loaded.shape().layers,
            loaded.shape().heads,
            loaded.shape().width
        ),
        (3, 2, 128)
    );
    assert_eq!(
        frmd_core::blob::LoadedMlp::load(bytes).err(),
        Some(frmd_core::blob::BlobError::BadMagic)
    );

    let report = equiv_within_bounds(student, baked, 5, 32);
    assert_eq!(row(&report, "int8 transformer layer mismatches"), 0.0);

    // `frmd export --activations int16`: the int16 blob (format 5 trailer) loads only with the
    // int16 loader and passes the same harness, its layers equal to the wide model.
    let baked16 = run.dir.join("int16");
    let cfg = frmd_host::export::ExportConfig {
        activations: Some("int16".into()),
        ..frmd_host::export::ExportConfig::for_checkpoint(student)
    };
    let exported16 = frmd_host::export::export_student(&cfg, false).unwrap();
    assert_eq!(exported16.activations(), frmd_export::Activations::Int16);
    frmd_host::export::write_export(&cfg, &exported16, Some(&baked16), None).unwrap();
    let blob16 = std::fs::read(baked16.join("policy.blob")).unwrap();
    let aligned16 = AlignedBlob::new(&blob16);
    assert!(frmd_core::blob::LoadedTransformer16::load(aligned16.bytes()).is_ok());
    assert_eq!(
        frmd_core::blob::LoadedTransformer::load(aligned16.bytes()).err(),
        Some(frmd_core::blob::BlobError::ActivationBits { found: 16 })
    );
    let module = std::fs::read_to_string(baked16.join("policy.rs")).unwrap();
    assert!(
        module.contains("pub const ACTIVATION_BITS: u8 = 16;"),
        "policy.rs"
    );
    let report16 = equiv_within_bounds(student, &baked16, 5, 32);
    assert_eq!(row(&report16, "int16 transformer layer mismatches"), 0.0);
    let _ = std::fs::remove_dir_all(&run.dir);
}
