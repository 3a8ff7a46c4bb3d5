//! End-to-end: a randomly initialized transformer-lite checkpoint written with the safetensors
//! crate is read, folded, calibrated, quantized and sampled by the int8 and f32 paths.

use super::*;
use crate::calibrate::{CalibrationSet, RangeMethod};
use crate::checkpoint::{
    expected_tensors, CheckpointMeta, HeadConfig, Normalization, Normalizer, CONFIG_FILE,
    WEIGHTS_FILE,
};
use frmd_core::policy::{F32TransformerNetwork, Int8TransformerNetwork, Network};
use frmd_core::rng::Rng;
use std::path::PathBuf;

fn lite_config() -> ModelConfig {
    ModelConfig {
        obs_dim: 5,
        history: 2,
        action_dim: 3,
        horizon: 8,
        control_dt: 0.05,
        embed_dim: 16,
        backbone: BackboneConfig::parse("transformer-lite").unwrap(),
        head: HeadConfig::ProDmp { num_basis: 4 },
    }
}

/// Writes `frmd.json` + `model.safetensors` with random weights of the right names and shapes
/// into a fresh temporary directory.
fn write_checkpoint(name: &str, config: &ModelConfig, seed: u64) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("frmd-tfexport-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut meta = CheckpointMeta::describe(Role::Student, config, SigmaConfig::default());
    meta.normalization = Some(Normalization {
        obs: Normalizer { min: vec![-1.0; config.obs_dim], max: vec![1.0; config.obs_dim] },
        action: Normalizer { min: vec![-1.0; config.action_dim], max: vec![1.0; config.action_dim] },
    });
    std::fs::write(dir.join(CONFIG_FILE), serde_json::to_string_pretty(&meta).unwrap()).unwrap();
    let mut rng = Rng::new(seed);
    let data: Vec<(String, Vec<usize>, Vec<u8>)> = expected_tensors(config)
        .into_iter()
        .map(|spec| {
            let len: usize = spec.shape.iter().product();
            let fan_in = spec.shape.get(1).copied().unwrap_or(1) as f32;
            let values: Vec<f32> = (0..len)
                .map(|_| {
                    let g = rng.gaussian();
                    if spec.name.ends_with("norm1.weight")
                        || spec.name.ends_with("norm2.weight")
                        || spec.name.ends_with("final_norm.weight")
                    {
                        1.0 + 0.1 * g
                    } else if spec.shape.len() == 2 && !spec.name.ends_with("pos_embedding") {
                        g / fan_in.sqrt()
                    } else {
                        0.1 * g
                    }
                })
                .collect();
            (spec.name, spec.shape, values.iter().flat_map(|v| v.to_le_bytes()).collect())
        })
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = data
        .iter()
        .map(|(name, shape, bytes)| {
            (name.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes).unwrap())
        })
        .collect();
    std::fs::write(dir.join(WEIGHTS_FILE), safetensors::serialize(views, None).unwrap()).unwrap();
    dir
}

fn calibration_set(config: &ModelConfig, rows: usize, seed: u64) -> CalibrationSet {
    let mut rng = Rng::new(seed);
    let cond = (0..rows * config.cond_dim()).map(|_| (0.5 * rng.gaussian()).clamp(-1.0, 1.0)).collect();
    CalibrationSet { cond_dim: config.cond_dim(), cond, seed }
}

/// Max and mean absolute int8-vs-f32 chunk error (normalized action units) over the rows of
/// `set`, and the spread of the f32 chunks.
fn chunk_error(quantized: &QuantizedTransformer, set: &CalibrationSet) -> (f32, f32, f32) {
    let f = &quantized.folded;
    let (mut max, mut sum, mut count) = (0.0f32, 0.0f64, 0usize);
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for row in 0..set.rows() {
        let cond = &set.cond[row * set.cond_dim..(row + 1) * set.cond_dim];
        let noise = set.noise(row, f.steps.len(), f.config.traj_dim());
        let want = f.sample(cond, &noise, |_, _, _| {}).unwrap();
        let got = quantized.sample(cond, &noise).unwrap();
        for (g, w) in got.iter().zip(&want) {
            max = max.max((g - w).abs());
            sum += f64::from((g - w).abs());
            count += 1;
            lo = lo.min(*w);
            hi = hi.max(*w);
        }
    }
    (max, (sum / count as f64) as f32, hi - lo)
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
        let quantized = quantize(&folded, &ranges).unwrap();
        let held_out = calibration_set(&config, 16, 99);
        let (max, mean, spread) = chunk_error(&quantized, &held_out);
        println!("transformer-lite, {steps} step(s): int8 vs f32 chunk max {max:.5}, mean {mean:.5}, f32 spread {spread:.3} (normalized units)");
        assert!(spread > 0.1, "f32 chunks are degenerate (spread {spread})");
        assert!(max <= 0.025 * spread, "max error {max} exceeds 2.5% of the f32 spread {spread}");
        assert!(mean <= 0.0075 * spread, "mean error {mean} exceeds 0.75% of the f32 spread {spread}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn adapters_run_the_exported_model_behind_the_network_trait() {
    let config = lite_config();
    let dir = write_checkpoint("adapter", &config, 12);
    let ckpt = Checkpoint::read(&dir).unwrap();
    let folded = FoldedTransformer::new(&ckpt, 2).unwrap();
    let ranges = calibrate(&folded, &calibration_set(&config, 8, 3), RangeMethod::MinMax).unwrap();
    let quantized = quantize(&folded, &ranges).unwrap();
    let tokens = folded.flat_noise_tokens();
    let f32_blocks = folded.f32_blocks();
    let int8_blocks = quantized.int8_blocks();
    let mut f32_scratch = Box::new(HostScratch::new());
    let mut int8_scratch = Box::new(HostScratch::new());
    let mut f32_net =
        F32TransformerNetwork::new(folded.view(&f32_blocks, 0).unwrap(), &folded.layout, &tokens, &mut f32_scratch).unwrap();
    let mut int8_net =
        Int8TransformerNetwork::new(quantized.view(&int8_blocks, 0).unwrap(), &folded.layout, &tokens, &mut int8_scratch)
            .unwrap();
    assert_eq!(f32_net.num_first_layer_biases(), 2);
    assert_eq!(int8_net.input_width(), config.cond_dim() + config.traj_dim());
    let mut rng = Rng::new(4);
    let cond: Vec<f32> = (0..config.cond_dim()).map(|_| 0.3 * rng.gaussian()).collect();
    let x: Vec<f32> = (0..config.traj_dim()).map(|_| rng.gaussian()).collect();
    for (i, step) in folded.steps.iter().enumerate() {
        let input = crate::fold::model_input(&config, &folded.layout, step, &cond, &x).unwrap();
        let mut out = vec![0.0; config.output_dim()];
        f32_net.forward(i, &input, &mut out).unwrap();
        assert_eq!(out, folded.forward_observed(i, &input, |_, _| {}).unwrap(), "f32 step {i}");
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
    assert!(error.to_string().contains("not a transformer checkpoint"), "{error}");
    std::fs::remove_dir_all(&dir).unwrap();

    let config = lite_config();
    let dir = write_checkpoint("teacher", &config, 2);
    let mut ckpt = Checkpoint::read(&dir).unwrap();
    ckpt.meta.role = Role::Teacher;
    let error = FoldedTransformer::new(&ckpt, 1).unwrap_err();
    assert!(error.to_string().contains("only student checkpoints"), "{error}");
    let ckpt = Checkpoint::read(&dir).unwrap();
    let error = FoldedTransformer::new(&ckpt, 5).unwrap_err();
    assert!(error.to_string().contains("1..=4"), "{error}");
    std::fs::remove_dir_all(&dir).unwrap();
}
