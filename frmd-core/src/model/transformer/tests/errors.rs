//! Every named error of the transformer forward passes is reachable and reported as documented.

extern crate std;

use super::fixture::{big_scratch, calibrated, random_inputs, BothForms, FloatModel, QuantModel};
use super::SMALL;
use crate::kernels::{Activation, KernelError};
use crate::model::linear::QuantizedLinear;
use crate::model::transformer::*;
use crate::quant::QuantParams;
use crate::rng::Rng;

/// `net` with a copy of its blocks changed by `edit`, validated.
fn validate_edited<'a, I, L, FF>(
    net: &Transformer<'a, I, L, FF>,
    edit: impl FnOnce(&mut [Block<'a, L, FF>]),
) -> Result<(), TransformerError>
where
    I: CheckedLinear,
    L: BlockLinear,
    FF: FeedForward,
{
    let mut blocks = net.blocks.to_vec();
    edit(&mut blocks);
    Transformer {
        blocks: &blocks,
        ..*net
    }
    .validate()
}

/// The [`SMALL`] model of `seed` calibrated on 10 inputs from `Rng::new(inputs)`, and that
/// stream, which the test goes on drawing from.
fn small_model(seed: u64, inputs: u64) -> (Rng, FloatModel, QuantModel) {
    let mut rng = Rng::new(inputs);
    let (model, quant) = calibrated(SMALL, seed, &mut rng, 10);
    (rng, model, quant)
}

#[test]
fn named_errors_for_bad_shapes_weights_and_arguments() {
    let (mut rng, model, quant) = small_model(21, 22);
    let forms = BothForms::new(&model, &quant);
    let (net, int8) = forms.views(false);
    let (trajectory, condition) = random_inputs(&mut rng, &SMALL);
    let mut out = [0.0_f32; 8];
    let mut scratch = big_scratch();
    let mut run_f32 = |n: &F32Transformer<'_>, t: &[f32], c: &[f32], o: &mut [f32]| {
        n.forward(t, c, o, &mut *scratch)
    };
    use TransformerError as E;
    // Shapes.
    let shape = |s: TransformerShape| F32Transformer { shape: s, ..net }.validate();
    assert_eq!(
        shape(TransformerShape { heads: 0, ..SMALL }),
        Err(E::ZeroSize)
    );
    assert_eq!(
        shape(TransformerShape { heads: 3, ..SMALL }),
        Err(E::HeadsDoNotDivideWidth)
    );
    let huge = TransformerShape {
        horizon: usize::MAX / 4,
        ..SMALL
    };
    assert_eq!(shape(huge), Err(E::SizeOverflow));
    assert_eq!(
        shape(TransformerShape { layers: 3, ..SMALL }),
        Err(E::LayerCount)
    );
    assert_eq!(
        shape(TransformerShape { output: 9, ..SMALL }),
        Err(E::Features { part: Part::Head })
    );
    assert_eq!(
        shape(TransformerShape {
            cond_dim: 5,
            ..SMALL
        }),
        Err(E::Features { part: Part::CondIn })
    );
    // Weights.
    let short_positions = F32Transformer {
        positions: &model.positions[1..],
        ..net
    };
    let short_noise = F32Transformer {
        noise_token: &model.noise_token[1..],
        ..net
    };
    for (edited, part) in [
        (short_positions, Part::Positions),
        (short_noise, Part::NoiseToken),
    ] {
        assert_eq!(edited.validate(), Err(E::Features { part }));
    }
    assert_eq!(
        validate_edited(&net, |b| {
            b[1].qkv.out_features = 47;
            b[1].qkv.weights = &model.blocks[1].qkv.weights[..47 * 16];
            b[1].qkv.bias = &model.blocks[1].qkv.bias[..47];
        }),
        Err(E::Features {
            part: Part::Qkv { layer: 1 }
        })
    );
    assert_eq!(
        validate_edited(&net, |b| {
            b[0].proj.weights = &model.blocks[0].proj.weights[1..];
        }),
        Err(E::Weights {
            part: Part::Proj { layer: 0 },
            error: KernelError::WeightsLength
        })
    );
    assert_eq!(
        validate_edited(&net, |b| {
            b[0].feed_forward.fc1.activation = Activation::Gelu;
        }),
        Err(E::Activation {
            part: Part::Fc1 { layer: 0 }
        })
    );
    assert_eq!(
        validate_edited(&net, |b| {
            b[1].norm2.beta = &model.blocks[1].norm2.beta[..15];
        }),
        Err(E::Features {
            part: Part::Norm2 { layer: 1 }
        })
    );
    // Arguments.
    assert_eq!(
        run_f32(&net, &trajectory[1..], &condition, &mut out),
        Err(E::TrajectoryLength)
    );
    assert_eq!(
        run_f32(&net, &trajectory, &condition[1..], &mut out),
        Err(E::ConditionLength)
    );
    assert_eq!(
        run_f32(&net, &trajectory, &condition, &mut out[1..]),
        Err(E::OutputLength)
    );
    let mut nan = trajectory.clone();
    nan[2] = f32::NAN;
    assert_eq!(
        run_f32(&net, &nan, &condition, &mut out),
        Err(E::NonFiniteInput)
    );
    assert_eq!(run_f32(&net, &trajectory, &condition, &mut out), Ok(()));
    // int8-specific parts.
    let mut int8_scratch = big_scratch();
    assert_eq!(
        int8.forward(&nan, &condition, &mut out, &mut *int8_scratch),
        Err(E::NonFiniteInput)
    );
    let bad_input = QuantizedLinear {
        input: QuantParams {
            scale: 0.0,
            zero_point: 0,
        },
        ..int8.head
    };
    let head = Int8Transformer {
        head: bad_input,
        ..int8
    };
    assert_eq!(head.validate(), Err(E::InputParams { part: Part::Head }));
    assert_eq!(
        validate_edited(&int8, |b| {
            b[1].feed_forward.fc1.requant.shifts = &quant.blocks[1].shifts[1..];
        }),
        Err(E::Weights {
            part: Part::Fc1 { layer: 1 },
            error: KernelError::RequantLength
        })
    );
    assert_eq!(
        validate_edited(&int8, |b| {
            b[0].feed_forward.fc2.linear.output_scales = &quant.blocks[0].fc2.output_scales[1..];
        }),
        Err(E::Weights {
            part: Part::Fc2 { layer: 0 },
            error: KernelError::ScaleLength
        })
    );
    assert_eq!(
        validate_edited(&int8, |b| {
            b[0].qkv.linear.output_scales = &quant.blocks[0].qkv.output_scales[..47];
        }),
        Err(E::Weights {
            part: Part::Qkv { layer: 0 },
            error: KernelError::ScaleLength
        })
    );
    let traj = Int8Transformer {
        traj_in: int8.cond_in,
        ..int8
    };
    assert_eq!(traj.validate(), Err(E::Features { part: Part::TrajIn }));
    // Noise-token folding.
    let mut token = [0.0_f32; 16];
    let noise_in = model.noise_in.view();
    let fold = |embedding: &[f32], token: &mut [f32]| {
        fold_noise_token(&SMALL, &noise_in, embedding, &model.positions, token)
    };
    assert_eq!(
        fold(&model.embedding[1..], &mut token),
        Err(E::EmbeddingLength)
    );
    assert_eq!(
        fold(&model.embedding, &mut token[1..]),
        Err(E::Features {
            part: Part::NoiseToken
        })
    );
    assert_eq!(fold(&model.embedding, &mut token), Ok(()));
    assert_eq!(token.as_slice(), model.noise_token.as_slice());
}

/// Corrupts one random size or slice of a valid model (or passes wrong argument lengths) many
/// times; every forward pass must return (most with an error), none may panic.
#[test]
fn random_corruptions_return_errors_without_panicking() {
    use crate::model::linear::F32Linear;
    let (mut rng, model, quant) = small_model(31, 32);
    let forms = BothForms::new(&model, &quant);
    let (net, int8) = forms.views(false);
    let floats = std::vec![0.25_f32; 4096];
    let codes = std::vec![1_i8; 4096];
    let words = std::vec![0_i32; 4096];
    let mut scratch = big_scratch();
    let mut output = std::vec![0.0_f32; 64];
    let (mut ok, mut failed) = (0_usize, 0_usize);
    let mut pick = |n: usize| rng.next_u32() as usize % n;
    for _ in 0..3000 {
        let (mut f, mut q) = (net, int8);
        let (mut f_blocks, mut q_blocks) = (net.blocks.to_vec(), int8.blocks.to_vec());
        let size = pick(40);
        let layer = pick(2);
        match pick(14) {
            0 => (f.shape.horizon, q.shape.horizon) = (size, size),
            1 => (f.shape.width, q.shape.width) = (size, size),
            2 => (f.shape.heads, q.shape.heads) = (size, size),
            3 => (f.shape.output, q.shape.output) = (size, size),
            4 => (f.shape.layers, q.shape.layers) = (size, size),
            5 => (f.positions, q.positions) = (&floats[..size * 8], &floats[..size * 8]),
            6 => (f.noise_token, q.noise_token) = (&floats[..size], &floats[..size]),
            7 => {
                f_blocks[layer].qkv.weights = &floats[..size * 16];
                q_blocks[layer].qkv.linear.fc.weights = &codes[..size * 16];
            }
            8 => {
                f_blocks[layer].feed_forward.fc1.out_features = size;
                q_blocks[layer].feed_forward.fc1.fc.out_features = size;
            }
            9 => {
                f_blocks[layer].norm2.gamma = &floats[..size];
                q_blocks[layer].norm1.beta = &floats[..size];
            }
            10 => {
                f.head.bias = &floats[..size];
                q.head.linear.output_scales = &floats[..size];
            }
            11 => q_blocks[layer].feed_forward.fc1.requant.shifts = &words[..size * 4],
            12 => {
                let layer = F32Linear {
                    in_features: size % 4,
                    out_features: 16,
                    weights: &floats[..(size % 4) * 16],
                    bias: &floats[..16],
                    activation: Activation::Identity,
                };
                (f.traj_in, q.traj_in) = (layer, TokenLinear::Float(layer));
            }
            _ => {}
        }
        (f.blocks, q.blocks) = (&f_blocks, &q_blocks);
        let right = pick(2) == 0;
        let len = |correct: usize, random: usize| if right { correct } else { random };
        let trajectory = &floats[..len(SMALL.trajectory_len(), pick(10))];
        let condition = &floats[..len(SMALL.cond_dim, pick(10))];
        let out = &mut output[..len(SMALL.output, pick(10))];
        for result in [
            f.forward(trajectory, condition, out, &mut *scratch),
            q.forward(trajectory, condition, out, &mut *scratch),
        ] {
            match result {
                Ok(()) => ok += 1,
                Err(_) => failed += 1,
            }
        }
    }
    std::eprintln!("random corruptions: {ok} forward passes succeeded, {failed} refused");
    assert!(ok > 300 && failed > 3000, "{ok} ok, {failed} failed");
}
