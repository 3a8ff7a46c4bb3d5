//! End-to-end: a randomly initialized transformer-lite checkpoint written with the safetensors
//! crate is read, folded, calibrated, quantized and sampled by the int8 and f32 paths (int16
//! activations: `tests16.rs`).

use super::*;
use crate::calibrate::RangeMethod;
use crate::host::HostScratch;
use frmd_core::blob::AlignedBlob;
use frmd_core::policy::{F32TransformerNetwork, Int8TransformerNetwork, Network};
use frmd_core::rng::Rng;
use frmd_formats::calibration::CalibrationSet;
use frmd_formats::checkpoint::{
    BackboneConfig, Checkpoint, HeadConfig, ModelConfig, Normalization, Role,
};
use frmd_test_support::checkpoint::{scratch_dir, unit_normalization, Init};
use std::path::PathBuf;

pub(super) fn lite_config() -> ModelConfig {
    ModelConfig {
        obs_dim: 5,
        history: 2,
        action_dim: 3,
        horizon: 8,
        control_dt: 0.05,
        embed_dim: 16,
        backbone: BackboneConfig::parse("transformer-lite").unwrap(),
        head: HeadConfig::prodmp(4),
    }
}

/// A student checkpoint of `config` with random weights drawn like a trained transformer's, in
/// a fresh temporary directory.
pub(super) fn write_checkpoint(name: &str, config: &ModelConfig, seed: u64) -> PathBuf {
    let dir = scratch_dir(&format!("tfexport-{name}"));
    let norm = unit_normalization(config.obs_dim, config.action_dim);
    frmd_test_support::checkpoint::write_checkpoint(
        &dir,
        Role::Student,
        config,
        norm,
        seed,
        Init::Transformer,
    );
    dir
}

pub(super) fn calibration_set(config: &ModelConfig, rows: usize, seed: u64) -> CalibrationSet {
    frmd_test_support::checkpoint::calibration_rows(config, rows, seed, seed)
}

/// Absolute int8-vs-f32 chunk errors and the spread of the f32 chunks.
pub(super) struct ChunkError {
    pub(super) max: f32,
    sum: f64,
    count: usize,
    lo: f32,
    hi: f32,
}

impl ChunkError {
    pub(super) fn new() -> Self {
        ChunkError {
            max: 0.0,
            sum: 0.0,
            count: 0,
            lo: f32::MAX,
            hi: f32::MIN,
        }
    }

    pub(super) fn add(&mut self, got: f32, want: f32) {
        self.max = self.max.max((got - want).abs());
        self.sum += f64::from((got - want).abs());
        self.count += 1;
        self.lo = self.lo.min(want);
        self.hi = self.hi.max(want);
    }

    /// Prints the errors of `what` (in `units`) and asserts the int8 chunks track the f32 ones:
    /// max error within 2.5 % and mean error within 0.75 % of the f32 spread.
    /// Mean absolute error.
    pub(super) fn mean(&self) -> f32 {
        (self.sum / self.count as f64) as f32
    }

    pub(super) fn assert_tracks(&self, what: &str, units: &str) {
        let (max, spread) = (self.max, self.hi - self.lo);
        let mean = self.mean();
        println!("{what}: quantized vs f32 chunk max {max:.5}, mean {mean:.5}, f32 spread {spread:.3} ({units})");
        assert!(spread > 0.1, "f32 chunks are degenerate (spread {spread})");
        assert!(
            max <= 0.025 * spread,
            "max error {max} exceeds 2.5% of the f32 spread {spread}"
        );
        assert!(
            mean <= 0.0075 * spread,
            "mean error {mean} exceeds 0.75% of the f32 spread {spread}"
        );
    }
}

/// The int8-vs-f32 chunk errors (normalized action units) over the rows of `set`.
pub(super) fn chunk_error<P: WideCodes>(
    quantized: &QuantizedTransformer<P>,
    set: &CalibrationSet,
) -> ChunkError {
    let f = &quantized.folded;
    let mut error = ChunkError::new();
    for row in 0..set.rows() {
        let noise = set.noise(row, f.base.steps.len(), f.base.config.traj_dim());
        let want = f.sample(set.row(row), &noise, |_, _, _| {}).unwrap();
        let got = quantized.sample(set.row(row), &noise).unwrap();
        for (g, w) in got.iter().zip(&want) {
            error.add(*g, *w);
        }
    }
    error
}

#[test]
fn transformer_lite_checkpoint_exports_and_int8_chunk_tracks_f32() {
    let config = lite_config();
    let dir = write_checkpoint("lite", &config, 11);
    let ckpt = Checkpoint::read(&dir).unwrap();
    for steps in [1, 2] {
        let folded = FoldedTransformer::new(&ckpt, steps).unwrap();
        assert_eq!(folded.noise_tokens.len(), steps);
        assert_eq!(folded.shape.width, 128);
        let calibration = calibration_set(&config, 32, 5);
        let ranges = calibrate(&folded, &calibration, RangeMethod::MinMax).unwrap();
        assert_eq!(ranges.rows, 32);
        let quantized = quantize::<i8>(&folded, &ranges, 1.0).unwrap();
        let held_out = calibration_set(&config, 16, 99);
        chunk_error(&quantized, &held_out).assert_tracks(
            &format!("transformer-lite, {steps} step(s)"),
            "normalized units",
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn adapters_run_the_exported_model_behind_the_network_trait() {
    let config = lite_config();
    let dir = write_checkpoint("adapter", &config, 12);
    let ckpt = Checkpoint::read(&dir).unwrap();
    let folded = FoldedTransformer::new(&ckpt, 2).unwrap();
    let ranges = calibrate(
        &folded,
        &calibration_set(&config, 8, 3),
        RangeMethod::MinMax,
    )
    .unwrap();
    let quantized = quantize::<i8>(&folded, &ranges, 1.0).unwrap();
    let tokens = folded.flat_noise_tokens();
    let f32_blocks = folded.f32_blocks();
    let int8_blocks = quantized.quant_blocks();
    let mut f32_scratch = Box::new(HostScratch::new());
    let mut int8_scratch = Box::new(HostScratch::new());
    let layout = &folded.base.layout;
    let f32_model = folded.view(&f32_blocks, 0).unwrap();
    let mut f32_net =
        F32TransformerNetwork::new(f32_model, layout, &tokens, &mut *f32_scratch).unwrap();
    let int8_model = quantized.view(&int8_blocks, 0).unwrap();
    let mut int8_net =
        Int8TransformerNetwork::new(int8_model, layout, &tokens, &mut *int8_scratch).unwrap();
    assert_eq!(f32_net.num_noise_variants(), 2);
    assert_eq!(
        int8_net.input_width(),
        config.cond_dim() + config.traj_dim()
    );
    let mut rng = Rng::new(4);
    let cond: Vec<f32> = (0..config.cond_dim())
        .map(|_| 0.3 * rng.gaussian())
        .collect();
    let x: Vec<f32> = (0..config.traj_dim()).map(|_| rng.gaussian()).collect();
    for (i, step) in folded.base.steps.iter().enumerate() {
        let input =
            crate::fold::model_input(&config, &folded.base.layout, step, &cond, &x).unwrap();
        let mut out = vec![0.0; config.output_dim()];
        f32_net.forward(i, &input, &mut out).unwrap();
        assert_eq!(
            out,
            folded.forward_observed(i, &input, |_, _| {}).unwrap(),
            "f32 step {i}"
        );
        int8_net.forward(i, &input, &mut out).unwrap();
        assert_eq!(out, quantized.forward(i, &input).unwrap(), "int8 step {i}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn refuses_non_transformer_and_non_student_checkpoints() {
    let mut config = lite_config();
    config.backbone = BackboneConfig::parse("mlp:16").unwrap();
    let dir = write_checkpoint("mlp", &config, 1);
    let error = FoldedTransformer::new(&Checkpoint::read(&dir).unwrap(), 1).unwrap_err();
    assert!(
        format!("{error:#}").contains("folds with mlp::FoldedMlp"),
        "{error}"
    );
    std::fs::remove_dir_all(&dir).unwrap();

    let config = lite_config();
    let dir = write_checkpoint("teacher", &config, 2);
    let mut ckpt = Checkpoint::read(&dir).unwrap();
    ckpt.meta.role = Role::Teacher;
    let error = FoldedTransformer::new(&ckpt, 1).unwrap_err();
    assert!(
        format!("{error:#}").contains("only students can be exported"),
        "{error}"
    );
    let ckpt = Checkpoint::read(&dir).unwrap();
    let error = FoldedTransformer::new(&ckpt, 5).unwrap_err();
    assert!(format!("{error:#}").contains("1..=4"), "{error:#}");
    std::fs::remove_dir_all(&dir).unwrap();
}

type Lite<'a> = frmd_core::blob::LoadedTransformer<'a>;

pub(super) fn exported_lite(
    name: &str,
    steps: usize,
) -> (QuantizedTransformer, Normalization, PathBuf) {
    exported_lite_as::<i8>(name, steps, 1.0)
}

/// [`exported_lite`] with `P` activations and activation headroom `headroom`.
pub(super) fn exported_lite_as<P: WideCodes>(
    name: &str,
    steps: usize,
    headroom: f32,
) -> (QuantizedTransformer<P>, Normalization, PathBuf) {
    let config = lite_config();
    let dir = write_checkpoint(name, &config, 21);
    let ckpt = Checkpoint::read(&dir).unwrap();
    let folded = FoldedTransformer::new(&ckpt, steps).unwrap();
    let ranges = calibrate(
        &folded,
        &calibration_set(&config, 16, 7),
        RangeMethod::MinMax,
    )
    .unwrap();
    (
        quantize::<P>(&folded, &ranges, headroom).unwrap(),
        ckpt.meta.normalization.clone().unwrap(),
        dir,
    )
}

/// One random model input per sampling step of `folded` (condition `0.3 g`, trajectory `g`
/// from `Rng::new(seed)`).
pub(super) fn step_inputs(folded: &FoldedTransformer, seed: u64) -> Vec<Vec<f32>> {
    let config = &folded.base.config;
    let mut rng = Rng::new(seed);
    let cond: Vec<f32> = (0..config.cond_dim())
        .map(|_| 0.3 * rng.gaussian())
        .collect();
    let x: Vec<f32> = (0..config.traj_dim()).map(|_| rng.gaussian()).collect();
    let layout = &folded.base.layout;
    folded
        .base
        .steps
        .iter()
        .map(|step| crate::fold::model_input(config, layout, step, &cond, &x).unwrap())
        .collect()
}

#[test]
fn blob_round_trip_is_bit_exact_and_drives_the_core_policy() {
    use frmd_core::policy::{Noise, Policy};
    let (quantized, norm, dir) = exported_lite("blob", 2);
    let bytes = quantized.blob(&norm).unwrap();
    let aligned = AlignedBlob::new(&bytes);
    let loaded = Lite::load(aligned.bytes()).unwrap();
    assert_eq!(loaded.steps(), &quantized.folded.base.steps[..]);
    let mut scratch = Box::new(HostScratch::new());
    let mut network = loaded.network(&mut *scratch).unwrap();
    assert_eq!(network.num_noise_variants(), 2);
    // Same int8 outputs as the exporter's in-memory model, per step, bit for bit.
    for (i, input) in step_inputs(&quantized.folded, 8).iter().enumerate() {
        let mut out = vec![0.0; lite_config().output_dim()];
        network.forward(i, input, &mut out).unwrap();
        assert_eq!(out, quantized.forward(i, input).unwrap(), "step {i}");
    }
    // The loaded blob runs frmd-core's Policy end to end and yields finite chunks.
    let mut policy = Policy::<_, 2, 5, 3, 8, 5, 64>::new(loaded.config(), network).unwrap();
    policy.reset(&[0.1, -0.2, 0.3]).unwrap();
    policy.observe(&[0.5, -0.5, 0.25, 0.0, 0.9]).unwrap();
    let mut noise_rng = Rng::new(3);
    policy.act(Noise::Rng(&mut noise_rng)).unwrap();
    let first = policy.next_action().unwrap();
    assert!(first.iter().all(|v| v.is_finite()));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn blob_loader_rejects_damage_by_name() {
    use frmd_core::blob::transformer::TensorField;
    use frmd_core::blob::{BlobError, Dimension, TransformerSection};
    use frmd_core::model::transformer::{Part, TransformerError};
    let (quantized, norm, dir) = exported_lite("damage", 1);
    let bytes = quantized.blob(&norm).unwrap();
    let load = |b: &[u8], shift: usize| Lite::load(AlignedBlob::shifted(b, shift).bytes()).err();
    assert_eq!(load(&bytes, 0).map(|e| e.to_string()), None);
    assert_eq!(
        load(&bytes[..bytes.len() - 1], 0),
        Some(BlobError::Truncated)
    );
    assert_eq!(load(&bytes[..10], 0), Some(BlobError::Truncated));
    let mut bad_magic = bytes.clone();
    bad_magic[3] = b'D';
    assert_eq!(load(&bad_magic, 0), Some(BlobError::BadMagic));
    let mut flipped = bytes.clone();
    *flipped.last_mut().unwrap() ^= 0x40;
    assert!(matches!(
        load(&flipped, 0),
        Some(BlobError::CrcMismatch { .. })
    ));
    assert!(matches!(
        load(&bytes, 1),
        Some(BlobError::SectionMisaligned(_))
    ));
    let aligned = AlignedBlob::new(&bytes);
    let expected = frmd_core::policy::PolicyDims {
        history: 2,
        obs_dim: 5,
        action_dim: 4,
        horizon: 8,
        params_per_dof: 5,
    };
    let wrong_dims = Lite::load(aligned.bytes()).and_then(|loaded| loaded.check_dims(&expected));
    assert_eq!(
        wrong_dims.err(),
        Some(BlobError::DimensionMismatch(Dimension::ActionDim))
    );
    // Mismatched shapes: a head with one weight row missing, NaN in a norm.
    let mut short_head = quantized.clone();
    let row = short_head.head.in_features;
    short_head
        .head
        .weights
        .truncate(short_head.head.weights.len() - row);
    let err = load(&short_head.blob(&norm).unwrap(), 0);
    assert!(
        matches!(
            err,
            Some(BlobError::Transformer(TransformerError::Weights {
                part: Part::Head,
                ..
            }))
        ),
        "{err:?}"
    );
    let mut nan_norm = quantized.clone();
    nan_norm.blocks[0].norm2.gamma[3] = f32::NAN;
    let err = load(&nan_norm.blob(&norm).unwrap(), 0);
    assert_eq!(
        err,
        Some(BlobError::NonFinite(
            TransformerSection {
                part: Part::Norm2 { layer: 0 },
                field: TensorField::Gamma
            }
            .into()
        ))
    );
    // An MLP loader refuses a transformer blob by magic.
    let mlp = frmd_core::blob::LoadedMlp::load(aligned.bytes());
    assert_eq!(mlp.err(), Some(BlobError::BadMagic));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// frmd-core's `Policy` over the blob-loaded int8 network and over the f32 network, same
/// observations and noise: chunk positions in robot units agree within 2.5% of the f32 spread
/// (max) and 0.75% (mean).
#[test]
fn core_policy_int8_blob_chunk_tracks_f32_policy_chunk() {
    use frmd_core::policy::{Noise, Policy};
    let (quantized, norm, dir) = exported_lite("policy", 1);
    let bytes = quantized.blob(&norm).unwrap();
    let aligned = AlignedBlob::new(&bytes);
    let loaded = Lite::load(aligned.bytes()).unwrap();
    let mut int8_scratch = Box::new(HostScratch::new());
    let mut int8 = Policy::<_, 2, 5, 3, 8, 5, 64>::new(
        loaded.config(),
        loaded.network(&mut *int8_scratch).unwrap(),
    )
    .unwrap();
    let folded = &quantized.folded;
    let tokens = folded.flat_noise_tokens();
    let f32_blocks = folded.f32_blocks();
    let mut f32_scratch = Box::new(HostScratch::new());
    let f32_net = F32TransformerNetwork::new(
        folded.view(&f32_blocks, 0).unwrap(),
        &folded.base.layout,
        &tokens,
        &mut *f32_scratch,
    )
    .unwrap();
    let mut float = Policy::<_, 2, 5, 3, 8, 5, 64>::new(loaded.config(), f32_net).unwrap();
    let mut rng = Rng::new(17);
    let mut error = ChunkError::new();
    for episode in 0..8 {
        let start: [f32; 3] = std::array::from_fn(|_| 0.5 * rng.gaussian());
        int8.reset(&start).unwrap();
        float.reset(&start).unwrap();
        for _ in 0..2 {
            let obs: [f32; 5] = std::array::from_fn(|_| (0.5 * rng.gaussian()).clamp(-1.0, 1.0));
            int8.observe(&obs).unwrap();
            float.observe(&obs).unwrap();
        }
        let noise: Vec<f32> = (0..24).map(|_| rng.gaussian()).collect();
        let got = int8.act(Noise::Given(&noise)).unwrap().positions;
        let want = float.act(Noise::Given(&noise)).unwrap().positions;
        for (g, w) in got.iter().flatten().zip(want.iter().flatten()) {
            assert!(g.is_finite(), "episode {episode}");
            error.add(*g, *w);
        }
    }
    error.assert_tracks("core Policy, blob, transformer-lite", "robot units");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Check (d) for the transformer: the exported layers agree with the wide-integer model, and the
/// check notices a difference (an int32 overflow the kernel wraps and the i64 model does not).
#[test]
fn layer_check_passes_on_the_export_and_detects_accumulator_overflow() {
    let (quantized, _norm, dir) = exported_lite("layers", 1);
    let check = reference::check_layers(&quantized, 4, 1).unwrap();
    assert_eq!(check.mismatches, 0, "{:?}", check.first_mismatch);
    // 7 linear layer kinds (traj_in, cond_in, head + 4 per block) and fc1 once more, 8 rows each.
    assert_eq!(check.cases, (3 + 5 * quantized.blocks.len() as u64) * 8);
    let mut overflowing = quantized.clone();
    overflowing.head.bias[0] = i32::MAX;
    let check = reference::check_layers(&overflowing, 4, 1).unwrap();
    assert!(check.mismatches >= 1, "overflow not detected");
    assert!(check.first_mismatch.unwrap().starts_with("head"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn transformer_lite_refuses_gptq_rounding_by_name() {
    let config = lite_config();
    let dir = write_checkpoint("lite-gptq", &config, 11);
    let options = crate::ExportOptions {
        weight_rounding: Some(crate::WeightRounding::Gptq),
        ..Default::default()
    };
    let calibration = calibration_set(&config, 4, 5);
    let checkpoint = Checkpoint::read(&dir).unwrap();
    let error = super::export(&checkpoint, &options, Activations::Int8, &calibration)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("gptq") && error.contains("nearest"),
        "{error}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
