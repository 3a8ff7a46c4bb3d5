//! Transformer tests: the f32 path against a naive f64 reference, the int8 path against the f32
//! path after calibration, named shape errors, scratch sizes and determinism.

extern crate std;

mod errors;
mod fixture;

use super::*;
use crate::kernels::{KernelError, LayerInput};
use crate::rng::Rng;
use fixture::{big_scratch, calibrated, random_inputs, BothForms, FloatModel};
use std::{vec, vec::Vec};

const SMALL: TransformerShape = TransformerShape {
    horizon: 3,
    action_dim: 2,
    cond_dim: 6,
    width: 16,
    heads: 2,
    layers: 2,
    output: 8,
};

/// transformer-lite with a 7-DoF ProDMP head (10 basis functions + goal) and 2 x 20 observations.
const LITE: TransformerShape = TransformerShape {
    horizon: 12,
    action_dim: 7,
    cond_dim: 54,
    width: 128,
    heads: 2,
    layers: 3,
    output: 77,
};

fn shapes() -> [TransformerShape; 4] {
    [
        SMALL,
        TransformerShape {
            horizon: 1,
            action_dim: 1,
            cond_dim: 3,
            width: 8,
            heads: 1,
            layers: 1,
            output: 3,
        },
        TransformerShape {
            horizon: 4,
            action_dim: 3,
            cond_dim: 10,
            width: 24,
            heads: 3,
            layers: 3,
            output: 12,
        },
        TransformerShape {
            horizon: 5,
            action_dim: 2,
            cond_dim: 7,
            width: 32,
            heads: 4,
            layers: 2,
            output: 11,
        },
    ]
}

#[test]
fn f32_path_matches_f64_reference() {
    let mut worst = 0.0_f64;
    for (index, shape) in shapes().into_iter().enumerate() {
        let model = FloatModel::random(shape, 100 + index as u64);
        let blocks = model.f32_blocks();
        let net = model.f32_view(&blocks);
        let mut scratch = big_scratch();
        let mut rng = Rng::new(7 + index as u64);
        for _ in 0..20 {
            let (trajectory, condition) = random_inputs(&mut rng, &shape);
            let mut out = vec![0.0_f32; shape.output];
            net.forward(&trajectory, &condition, &mut out, &mut *scratch)
                .unwrap();
            let want = model.reference(&trajectory, &condition);
            for (got, want) in out.iter().zip(&want) {
                let error = (f64::from(*got) - want).abs() / want.abs().max(1.0);
                worst = worst.max(error);
                assert!(error < 1e-5, "{shape:?}: {got} vs {want}");
            }
        }
    }
    std::eprintln!("f32 transformer vs f64 reference: max error {worst:.2e} (relative above 1)");
}

/// int8 path against f32 path: max and RMS abs error, and the f32 output range (max - min).
struct Comparison {
    max_error: f32,
    rms_error: f32,
    range: f32,
}

impl core::fmt::Display for Comparison {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let pct = |e: f32| 100.0 * e / self.range;
        write!(
            f,
            "max abs error {:.4} ({:.2}% of range {:.3}), rms {:.4} ({:.2}%)",
            self.max_error,
            pct(self.max_error),
            self.range,
            self.rms_error,
            pct(self.rms_error)
        )
    }
}

/// Calibrates on `runs.0` random inputs, then compares the int8 path with the f32 path over
/// `runs.1` other inputs.
fn int8_error(
    shape: TransformerShape,
    seed: u64,
    float_inputs: bool,
    runs: (usize, usize),
) -> Comparison {
    let mut rng = Rng::new(seed ^ 0xCA11);
    let (model, quant) = calibrated(shape, seed, &mut rng, runs.0);
    let forms = BothForms::new(&model, &quant);
    let (float_net, net) = forms.views(float_inputs);
    let mut scratch = big_scratch();
    let (mut max_error, mut lo, mut hi) = (0.0_f32, f32::MAX, f32::MIN);
    let (mut sum_sq, mut count) = (0.0_f64, 0_usize);
    for _ in 0..runs.1 {
        let (trajectory, condition) = random_inputs(&mut rng, &shape);
        let mut want = vec![0.0_f32; shape.output];
        float_net
            .forward(&trajectory, &condition, &mut want, &mut *scratch)
            .unwrap();
        let mut got = vec![0.0_f32; shape.output];
        net.forward(&trajectory, &condition, &mut got, &mut *scratch)
            .unwrap();
        for (g, w) in got.iter().zip(&want) {
            max_error = max_error.max((g - w).abs());
            sum_sq += f64::from(g - w).powi(2);
            count += 1;
            lo = lo.min(*w);
            hi = hi.max(*w);
        }
    }
    Comparison {
        max_error,
        rms_error: (sum_sq / count as f64).sqrt() as f32,
        range: hi - lo,
    }
}

/// Fails unless the int8 path is within 4% (max) and 1% (RMS) of the f32 output range.
fn assert_close(what: &str, c: &Comparison) {
    std::eprintln!("int8 vs f32 {what}: {c}");
    assert!(
        c.range > 1.0,
        "degenerate fixture: output range {}",
        c.range
    );
    assert!(c.max_error < 0.04 * c.range, "{what}: {c}");
    assert!(c.rms_error < 0.01 * c.range, "{what}: {c}");
}

#[test]
fn int8_path_close_to_f32_on_small_shapes() {
    for (index, shape) in shapes().into_iter().enumerate() {
        let comparison = int8_error(shape, 200 + index as u64, false, (200, 50));
        assert_close(&std::format!("{shape:?}"), &comparison);
    }
}

#[test]
fn int8_transformer_lite_close_to_f32() {
    assert_close("transformer-lite", &int8_error(LITE, 31, false, (48, 24)));
}

#[test]
fn int8_path_is_bit_exact_with_naive_integer_model() {
    for (index, shape) in shapes().into_iter().enumerate() {
        let mut rng = Rng::new(401 + index as u64);
        let (model, quant) = calibrated(shape, 400 + index as u64, &mut rng, 30);
        let int8_blocks = quant.blocks(&model);
        let net = quant.view(&model, &int8_blocks, false);
        let mut scratch = big_scratch();
        for _ in 0..10 {
            let (trajectory, condition) = random_inputs(&mut rng, &shape);
            let mut got = vec![0.0_f32; shape.output];
            net.forward(&trajectory, &condition, &mut got, &mut *scratch)
                .unwrap();
            let want = quant.naive_forward(&model, &trajectory, &condition);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
            assert_eq!(bits(&got), bits(&want), "{shape:?}");
        }
    }
}

#[test]
fn float_input_layers_are_supported_in_the_int8_path() {
    let int8_inputs = int8_error(SMALL, 300, false, (200, 50));
    let float_inputs = int8_error(SMALL, 300, true, (200, 50));
    assert_eq!(int8_inputs.range, float_inputs.range);
    assert_close("int8 input layers", &int8_inputs);
    assert_close("f32 input layers", &float_inputs);
    assert_ne!(
        float_inputs.max_error, int8_inputs.max_error,
        "the input layer variant was not used"
    );
}

#[test]
fn deterministic_and_independent_of_scratch_contents() {
    let mut rng = Rng::new(6);
    let (model, quant) = calibrated(SMALL, 5, &mut rng, 50);
    let forms = BothForms::new(&model, &quant);
    let (float_net, net) = forms.views(false);
    let (trajectory, condition) = random_inputs(&mut rng, &SMALL);
    let run = |dirty: bool| {
        let mut scratch = big_scratch();
        if dirty {
            let buffers = scratch.buffers();
            buffers.floats.fill(f32::NAN);
            buffers.codes.fill(-77);
            buffers.accumulators.fill(i32::MIN);
        }
        let mut float_out = [0.0_f32; 8];
        let mut int8_out = [0.0_f32; 8];
        float_net
            .forward(&trajectory, &condition, &mut float_out, &mut *scratch)
            .unwrap();
        net.forward(&trajectory, &condition, &mut int8_out, &mut *scratch)
            .unwrap();
        (float_out.map(f32::to_bits), int8_out.map(f32::to_bits))
    };
    let first = run(false);
    assert_eq!(first, run(false));
    assert_eq!(first, run(true));
    // The output depends on the inputs (not a constant).
    let mut moved = trajectory.clone();
    moved[0] += 0.5;
    let mut out = [0.0_f32; 8];
    net.forward(&moved, &condition, &mut out, &mut *big_scratch())
        .unwrap();
    assert_ne!(out.map(f32::to_bits), first.1);
}

#[test]
fn exact_scratch_sizes_suffice_and_one_less_fails() {
    const F: ScratchLens = SMALL.f32_scratch();
    const Q: ScratchLens = SMALL.int8_scratch();
    let mut rng = Rng::new(9);
    let (model, quant) = calibrated(SMALL, 8, &mut rng, 20);
    let forms = BothForms::new(&model, &quant);
    let (float_net, net) = forms.views(false);
    let (trajectory, condition) = random_inputs(&mut rng, &SMALL);
    let mut out = [0.0_f32; 8];
    let mut exact = TransformerScratch::<{ F.floats }, 0, 0>::new();
    assert_eq!(
        float_net.forward(&trajectory, &condition, &mut out, &mut exact),
        Ok(())
    );
    let mut short = TransformerScratch::<{ F.floats - 1 }, 0, 0>::new();
    assert_eq!(
        float_net.forward(&trajectory, &condition, &mut out, &mut short),
        Err(TransformerError::ScratchTooSmall {
            buffer: ScratchBuffer::Floats,
            needed: F.floats
        })
    );
    let mut exact = TransformerScratch::<{ Q.floats }, { Q.codes }, { Q.accumulators }>::new();
    assert_eq!(
        net.forward(&trajectory, &condition, &mut out, &mut exact),
        Ok(())
    );
    let too_small = |buffer, needed| Err(TransformerError::ScratchTooSmall { buffer, needed });
    let mut short = TransformerScratch::<{ Q.floats - 1 }, { Q.codes }, { Q.accumulators }>::new();
    assert_eq!(
        net.forward(&trajectory, &condition, &mut out, &mut short),
        too_small(ScratchBuffer::Floats, Q.floats)
    );
    let mut short = TransformerScratch::<{ Q.floats }, { Q.codes - 1 }, { Q.accumulators }>::new();
    assert_eq!(
        net.forward(&trajectory, &condition, &mut out, &mut short),
        too_small(ScratchBuffer::Codes, Q.codes)
    );
    let mut short = TransformerScratch::<{ Q.floats }, { Q.codes }, { Q.accumulators - 1 }>::new();
    assert_eq!(
        net.forward(&trajectory, &condition, &mut out, &mut short),
        too_small(ScratchBuffer::Accumulators, Q.accumulators)
    );
}

#[test]
fn transformer_lite_scratch_ram() {
    let f = LITE.f32_scratch();
    let q = LITE.int8_scratch();
    // T = 14, W = 128, hd = 64: int8 floats = TW + 2T hd + 2 hd + T + W.
    assert_eq!(q.floats, 1792 + 1792 + 128 + 14 + 128);
    assert_eq!(q.codes, 2 * 1792 + 512);
    assert_eq!(q.accumulators, 128);
    assert_eq!(q.ram_bytes(), 20_024);
    assert_eq!(f.floats, 3 * 1792 + 1792 + 64 + 14 + 5 * 128);
    assert_eq!(f.ram_bytes(), 31_544);
    // A head wider than W needs more accumulators; a long condition more bytes.
    let wide = TransformerShape {
        output: 300,
        cond_dim: 5000,
        ..LITE
    };
    assert_eq!(wide.int8_scratch().accumulators, 300);
    assert_eq!(wide.int8_scratch().codes, 5000);
}

#[test]
fn probes_report_every_quantization_point() {
    let model = FloatModel::random(SMALL, 11);
    let blocks = model.f32_blocks();
    let net = model.f32_view(&blocks);
    let mut rng = Rng::new(12);
    let (trajectory, condition) = random_inputs(&mut rng, &SMALL);
    let mut seen: Vec<(TransformerProbe, usize)> = Vec::new();
    let mut out = [0.0_f32; 8];
    net.forward_observed(
        &trajectory,
        &condition,
        &mut out,
        &mut *big_scratch(),
        |p, v| seen.push((p, v.len())),
    )
    .unwrap();
    let count = |probe| seen.iter().filter(|(p, _)| *p == probe).count();
    let len = |probe| seen.iter().find(|(p, _)| *p == probe).map(|(_, l)| *l);
    let (t, w) = (SMALL.tokens(), SMALL.width);
    assert_eq!(len(TransformerProbe::Trajectory), Some(6));
    assert_eq!(len(TransformerProbe::Condition), Some(6));
    assert_eq!(len(TransformerProbe::Tokens), Some(t * w));
    for layer in 0..SMALL.layers {
        assert_eq!(len(TransformerProbe::Norm1 { layer }), Some(t * w));
        assert_eq!(len(TransformerProbe::Attention { layer }), Some(t * w));
        assert_eq!(count(TransformerProbe::Norm2 { layer }), t);
        assert_eq!(len(TransformerProbe::Norm2 { layer }), Some(w));
        assert_eq!(count(TransformerProbe::Fc1 { layer }), t);
        assert_eq!(len(TransformerProbe::Gelu { layer }), Some(4 * w));
        assert_eq!(len(TransformerProbe::Block { layer }), Some(t * w));
    }
    assert_eq!(len(TransformerProbe::FinalNorm), Some(t * w));
    assert_eq!(len(TransformerProbe::Output), Some(8));
    // Trajectory, Condition, Tokens; per block Norm1, Attention, Block and 3 per token; then
    // FinalNorm and Output.
    assert_eq!(seen.len(), 3 + SMALL.layers * (3 + 3 * t) + 2);
}

#[test]
fn attend_averages_values_for_equal_scores() {
    let keys = [1.0_f32, 0.0, 1.0, 0.0, 1.0, 0.0];
    let values = [1.0_f32, 2.0, 3.0, 4.0, 5.0, 9.0];
    let mut scores = [0.0_f32; 3];
    let mut out = [0.0_f32; 2];
    attend(&[0.0, 1.0], &keys, &values, 0.5, &mut scores, &mut out).unwrap();
    assert_eq!(scores, [1.0 / 3.0; 3]);
    assert!((out[0] - 3.0).abs() < 1e-6 && (out[1] - 5.0).abs() < 1e-6);
    // A dominant key selects its value.
    let keys = [0.0_f32, 0.0, 50.0, 0.0, 0.0, 0.0];
    attend(&[1.0, 0.0], &keys, &values, 1.0, &mut scores, &mut out).unwrap();
    assert!((out[0] - 3.0).abs() < 1e-6 && (out[1] - 4.0).abs() < 1e-6);
    assert_eq!(
        attend(&[1.0, 0.0], &keys[..5], &values, 1.0, &mut scores, &mut out),
        Err(KernelError::InputLength)
    );
}

#[test]
fn int8_linear_rows_match_the_full_layer() {
    let mut rng = Rng::new(14);
    let (_, quant) = calibrated(SMALL, 13, &mut rng, 10);
    let qkv = quant.blocks[0].qkv.view();
    let input: Vec<i8> = (0..16).map(|i| (i * 13 - 100) as i8).collect();
    let mut full = [0.0_f32; 48];
    qkv.linear
        .forward_input(LayerInput::Int8(&input), &mut [0; 48], &mut full)
        .unwrap();
    for start in [0_usize, 8, 16, 40] {
        let mut part = [0.0_f32; 8];
        qkv.rows(start, 8)
            .unwrap()
            .linear
            .forward_input(LayerInput::Int8(&input), &mut [0; 8], &mut part)
            .unwrap();
        assert_eq!(part, full[start..start + 8]);
    }
    assert_eq!(qkv.rows(41, 8), Err(KernelError::WeightsLength));
    assert_eq!(qkv.rows(usize::MAX, 2), Err(KernelError::WeightsLength));
}
