//! Test fixtures: random f32 weights, a naive f64 reference forward pass written from the candle
//! module's definition, and calibration + quantization done the way the exporter will do it.

extern crate std;

use super::super::*;
use crate::kernels::{gelu_sigmoid, Activation, FcRequant, Lut8};
use crate::model::fixture::{quantize_layer, FloatLayer, QuantLayer, Range};
use crate::model::linear::{F32Linear, Int8Linear, QuantizedLinear, RequantizedLinear};
use crate::quant::{requantization_multiplier, QuantParams};
use crate::rng::Rng;
use std::collections::HashMap;
use std::{vec, vec::Vec};

/// Scratch large enough for every shape in these tests (transformer-lite included).
pub type BigScratch = TransformerScratch<8192, 4096, 256>;

pub fn big_scratch() -> std::boxed::Box<BigScratch> {
    std::boxed::Box::new(BigScratch::new())
}

/// A random f32 linear layer without activation (gain 1).
fn lin(rng: &mut Rng, in_features: usize, out_features: usize) -> FloatLayer {
    FloatLayer::random(rng, in_features, out_features, 1.0, Activation::Identity)
}

pub struct Norm {
    pub gamma: Vec<f32>,
    pub beta: Vec<f32>,
}

impl Norm {
    fn random(rng: &mut Rng, width: usize) -> Self {
        Self {
            gamma: (0..width).map(|_| 1.0 + 0.2 * rng.gaussian()).collect(),
            beta: (0..width).map(|_| 0.1 * rng.gaussian()).collect(),
        }
    }

    pub fn view(&self) -> LayerNormWeights<'_> {
        LayerNormWeights {
            gamma: &self.gamma,
            beta: &self.beta,
        }
    }

    fn apply64(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len() as f64;
        let mean = x.iter().sum::<f64>() / n;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        let inv = 1.0 / (var + 1e-5).sqrt();
        x.iter()
            .zip(&self.gamma)
            .zip(&self.beta)
            .map(|((v, g), b)| (v - mean) * inv * f64::from(*g) + f64::from(*b))
            .collect()
    }
}

pub struct BlockWeights {
    pub norm1: Norm,
    pub qkv: FloatLayer,
    pub proj: FloatLayer,
    pub norm2: Norm,
    pub fc1: FloatLayer,
    pub fc2: FloatLayer,
}

pub struct FloatModel {
    pub shape: TransformerShape,
    pub traj_in: FloatLayer,
    pub cond_in: FloatLayer,
    pub noise_in: FloatLayer,
    pub embedding: Vec<f32>,
    pub positions: Vec<f32>,
    pub blocks: Vec<BlockWeights>,
    pub final_norm: Norm,
    pub head: FloatLayer,
    pub noise_token: Vec<f32>,
}

fn gelu64(x: f64) -> f64 {
    x / (1.0 + (-1.702 * x).exp())
}

impl FloatModel {
    pub fn random(shape: TransformerShape, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let w = shape.width;
        let embed_dim = 6;
        let blocks = (0..shape.layers)
            .map(|_| BlockWeights {
                norm1: Norm::random(&mut rng, w),
                qkv: lin(&mut rng, w, 3 * w),
                proj: lin(&mut rng, w, w),
                norm2: Norm::random(&mut rng, w),
                fc1: lin(&mut rng, w, 4 * w),
                fc2: lin(&mut rng, 4 * w, w),
            })
            .collect();
        let mut model = Self {
            shape,
            traj_in: lin(&mut rng, shape.action_dim, w),
            cond_in: lin(&mut rng, shape.cond_dim, w),
            noise_in: lin(&mut rng, embed_dim, w),
            embedding: (0..embed_dim).map(|_| rng.gaussian()).collect(),
            positions: (0..shape.token_values())
                .map(|_| 0.5 * rng.gaussian())
                .collect(),
            blocks,
            final_norm: Norm::random(&mut rng, w),
            head: lin(&mut rng, shape.token_values(), shape.output),
            noise_token: vec![0.0; w],
        };
        fold_noise_token(
            &shape,
            &model.noise_in.view(),
            &model.embedding,
            &model.positions,
            &mut model.noise_token,
        )
        .unwrap();
        model
    }

    pub fn f32_blocks(&self) -> Vec<F32Block<'_>> {
        self.blocks
            .iter()
            .map(|b| F32Block {
                norm1: b.norm1.view(),
                qkv: b.qkv.view(),
                proj: b.proj.view(),
                norm2: b.norm2.view(),
                feed_forward: F32FeedForward {
                    fc1: F32Linear {
                        activation: Activation::GeluSigmoid,
                        ..b.fc1.view()
                    },
                    fc2: b.fc2.view(),
                },
            })
            .collect()
    }

    pub fn f32_view<'a>(&'a self, blocks: &'a [F32Block<'a>]) -> F32Transformer<'a> {
        F32Transformer {
            shape: self.shape,
            traj_in: self.traj_in.view(),
            cond_in: self.cond_in.view(),
            noise_token: &self.noise_token,
            positions: &self.positions,
            blocks,
            final_norm: self.final_norm.view(),
            head: self.head.view(),
        }
    }

    /// Naive f64 forward pass from the definition (full qkv matrix, all heads at once).
    pub fn reference(&self, trajectory: &[f32], condition: &[f32]) -> Vec<f64> {
        let s = &self.shape;
        let (w, t, hd) = (s.width, s.tokens(), s.head_dim());
        let to64 = |v: &[f32]| v.iter().map(|x| f64::from(*x)).collect::<Vec<f64>>();
        let pos = |i: usize| to64(&self.positions[i * w..(i + 1) * w]);
        let add = |a: Vec<f64>, b: Vec<f64>| a.iter().zip(&b).map(|(x, y)| x + y).collect();
        let mut h: Vec<Vec<f64>> = vec![
            add(self.cond_in.affine64(&to64(condition)), pos(0)),
            add(self.noise_in.affine64(&to64(&self.embedding)), pos(1)),
        ];
        for i in 0..s.horizon {
            let step = to64(&trajectory[i * s.action_dim..(i + 1) * s.action_dim]);
            h.push(add(self.traj_in.affine64(&step), pos(2 + i)));
        }
        for b in &self.blocks {
            let qkv: Vec<Vec<f64>> = h
                .iter()
                .map(|x| b.qkv.affine64(&b.norm1.apply64(x)))
                .collect();
            let mut attn = vec![vec![0.0_f64; w]; t];
            for head in 0..s.heads {
                let o = head * hd;
                for i in 0..t {
                    let scores: Vec<f64> = (0..t)
                        .map(|j| {
                            (0..hd)
                                .map(|d| qkv[i][o + d] * qkv[j][w + o + d])
                                .sum::<f64>()
                                / (hd as f64).sqrt()
                        })
                        .collect();
                    let m = scores.iter().cloned().fold(f64::MIN, f64::max);
                    let e: Vec<f64> = scores.iter().map(|x| (x - m).exp()).collect();
                    let z: f64 = e.iter().sum();
                    for d in 0..hd {
                        attn[i][o + d] = (0..t).map(|j| e[j] / z * qkv[j][2 * w + o + d]).sum();
                    }
                }
            }
            for i in 0..t {
                h[i] = add(h[i].clone(), b.proj.affine64(&attn[i]));
                let hidden: Vec<f64> = b
                    .fc1
                    .affine64(&b.norm2.apply64(&h[i]))
                    .into_iter()
                    .map(gelu64)
                    .collect();
                h[i] = add(h[i].clone(), b.fc2.affine64(&hidden));
            }
        }
        let flat: Vec<f64> = h.iter().flat_map(|x| self.final_norm.apply64(x)).collect();
        self.head.affine64(&flat)
    }
}

/// Inputs as the one-step student sees them: trajectory ~ N(0, 1), condition in [-1, 1].
pub fn random_inputs(rng: &mut Rng, shape: &TransformerShape) -> (Vec<f32>, Vec<f32>) {
    let trajectory = (0..shape.trajectory_len())
        .map(|_| rng.gaussian())
        .collect();
    let condition = (0..shape.cond_dim)
        .map(|_| (0.5 * rng.gaussian()).clamp(-1.0, 1.0))
        .collect();
    (trajectory, condition)
}

/// Min/max per probe over calibration runs of the f32 model.
pub struct Ranges(HashMap<TransformerProbe, Range>);

impl Ranges {
    pub fn calibrate(model: &F32Transformer<'_>, rng: &mut Rng, runs: usize) -> Self {
        let mut map: HashMap<TransformerProbe, Range> = HashMap::new();
        let mut scratch = big_scratch();
        let mut output = vec![0.0_f32; model.shape.output];
        for _ in 0..runs {
            let (trajectory, condition) = random_inputs(rng, &model.shape);
            model
                .forward_observed(
                    &trajectory,
                    &condition,
                    &mut output,
                    &mut *scratch,
                    |probe, values| map.entry(probe).or_insert_with(Range::new).add(values),
                )
                .unwrap();
        }
        Self(map)
    }

    pub fn params(&self, probe: TransformerProbe) -> QuantParams {
        self.0[&probe].params()
    }
}

/// A random f32 model of `shape` (weights from `seed`) and its int8 form, calibrated on `runs`
/// random inputs drawn from `rng`.
pub fn calibrated(
    shape: TransformerShape,
    seed: u64,
    rng: &mut Rng,
    runs: usize,
) -> (FloatModel, QuantModel) {
    let model = FloatModel::random(shape, seed);
    let blocks = model.f32_blocks();
    let ranges = Ranges::calibrate(&model.f32_view(&blocks), rng, runs);
    let quant = QuantModel::new(&model, &ranges);
    (model, quant)
}

/// The blocks of a calibrated model in both forms, which the two transformers borrow.
pub struct BothForms<'a> {
    model: &'a FloatModel,
    quant: &'a QuantModel,
    f32_blocks: Vec<F32Block<'a>>,
    int8_blocks: Vec<Int8Block<'a>>,
}

impl<'a> BothForms<'a> {
    pub fn new(model: &'a FloatModel, quant: &'a QuantModel) -> Self {
        Self {
            model,
            quant,
            f32_blocks: model.f32_blocks(),
            int8_blocks: quant.blocks(model),
        }
    }

    /// The f32 transformer and the int8 one (`float_inputs` as in [`QuantModel::view`]).
    pub fn views(&'a self, float_inputs: bool) -> (F32Transformer<'a>, Int8Transformer<'a>) {
        let float = self.model.f32_view(&self.f32_blocks);
        let int8 = self.quant.view(self.model, &self.int8_blocks, float_inputs);
        (float, int8)
    }
}

/// A linear layer quantized for input parameters `input` (exporter recipe).
pub struct QLin {
    pub input: QuantParams,
    pub layer: QuantLayer,
    pub output_scales: Vec<f32>,
}

impl QLin {
    pub fn new(lin: &FloatLayer, input: QuantParams) -> Self {
        let layer = quantize_layer(lin, &lin.bias, input, None);
        Self {
            input,
            output_scales: layer.output_scales(input),
            layer,
        }
    }

    pub fn view(&self) -> QuantizedLinear<'_> {
        QuantizedLinear {
            input: self.input,
            linear: Int8Linear {
                fc: self.layer.fully_connected(),
                output_scales: &self.output_scales,
            },
        }
    }
}

pub struct QBlock {
    pub qkv: QLin,
    pub proj: QLin,
    pub fc1: QLin,
    pub fc1_output: QuantParams,
    pub multipliers: Vec<i32>,
    pub shifts: Vec<i32>,
    pub gelu: Lut8,
    pub fc2: QLin,
}

pub struct QuantModel {
    pub traj_in: QLin,
    pub cond_in: QLin,
    pub blocks: Vec<QBlock>,
    pub head: QLin,
}

impl QuantModel {
    pub fn new(float: &FloatModel, ranges: &Ranges) -> Self {
        let blocks = float
            .blocks
            .iter()
            .enumerate()
            .map(|(layer, b)| {
                let fc1 = QLin::new(&b.fc1, ranges.params(TransformerProbe::Norm2 { layer }));
                let fc1_output = ranges.params(TransformerProbe::Fc1 { layer });
                let gelu_output = ranges.params(TransformerProbe::Gelu { layer });
                let (multipliers, shifts) = fc1
                    .layer
                    .weight_scales
                    .iter()
                    .map(|w| {
                        requantization_multiplier(fc1.input.scale, *w, fc1_output.scale).unwrap()
                    })
                    .unzip();
                QBlock {
                    qkv: QLin::new(&b.qkv, ranges.params(TransformerProbe::Norm1 { layer })),
                    proj: QLin::new(
                        &b.proj,
                        ranges.params(TransformerProbe::Attention { layer }),
                    ),
                    fc1,
                    fc1_output,
                    multipliers,
                    shifts,
                    gelu: Lut8::build(gelu_sigmoid, fc1_output, gelu_output).unwrap(),
                    fc2: QLin::new(&b.fc2, gelu_output),
                }
            })
            .collect();
        Self {
            traj_in: QLin::new(&float.traj_in, ranges.params(TransformerProbe::Trajectory)),
            cond_in: QLin::new(&float.cond_in, ranges.params(TransformerProbe::Condition)),
            blocks,
            head: QLin::new(&float.head, ranges.params(TransformerProbe::FinalNorm)),
        }
    }

    pub fn blocks<'a>(&'a self, float: &'a FloatModel) -> Vec<Int8Block<'a>> {
        self.blocks
            .iter()
            .zip(&float.blocks)
            .map(|(q, f)| Int8Block {
                norm1: f.norm1.view(),
                qkv: q.qkv.view(),
                proj: q.proj.view(),
                norm2: f.norm2.view(),
                feed_forward: Int8FeedForward {
                    input: q.fc1.input,
                    fc1: RequantizedLinear {
                        fc: q.fc1.view().linear.fc,
                        requant: FcRequant {
                            multipliers: &q.multipliers,
                            shifts: &q.shifts,
                            output_zero_point: q.fc1_output.zero_point,
                            activation_min: -128,
                            activation_max: 127,
                        },
                        activation: Some(&q.gelu.table),
                    },
                    fc2: q.fc2.view(),
                },
            })
            .collect()
    }

    /// The int8 model; `float_inputs` keeps `traj_in`/`cond_in` in f32.
    pub fn view<'a>(
        &'a self,
        float: &'a FloatModel,
        blocks: &'a [Int8Block<'a>],
        float_inputs: bool,
    ) -> Int8Transformer<'a> {
        let (traj_in, cond_in) = if float_inputs {
            (
                TokenLinear::Float(float.traj_in.view()),
                TokenLinear::Float(float.cond_in.view()),
            )
        } else {
            (
                TokenLinear::Quantized(self.traj_in.view()),
                TokenLinear::Quantized(self.cond_in.view()),
            )
        };
        Int8Transformer {
            shape: float.shape,
            traj_in,
            cond_in,
            noise_token: &float.noise_token,
            positions: &float.positions,
            blocks,
            final_norm: float.final_norm.view(),
            head: self.head.view(),
        }
    }
}

fn naive_accumulator(q: &QLin, o: usize, codes: &[i8]) -> i32 {
    i32::try_from(q.layer.naive_accumulator(o, codes)).expect("test accumulators fit i32")
}

/// Quantize, i64 dot products, dequantize (f32 in, f32 out).
fn naive_linear(q: &QLin, input: &[f32]) -> Vec<f32> {
    let codes: Vec<i8> = input.iter().map(|v| q.input.quantize(*v)).collect();
    (0..q.layer.out_features)
        .map(|o| naive_accumulator(q, o, &codes) as f32 * q.output_scales[o])
        .collect()
}

impl QuantModel {
    /// Naive int8 forward pass: full `qkv` matrices, i64 accumulation, the wide-integer
    /// requantization model, table lookups by index; f32 steps in the documented order.
    pub fn naive_forward(
        &self,
        float: &FloatModel,
        trajectory: &[f32],
        condition: &[f32],
    ) -> Vec<f32> {
        let s = &float.shape;
        let (w, t, hd) = (s.width, s.tokens(), s.head_dim());
        let add = |x: &mut [f32], y: &[f32]| x.iter_mut().zip(y).for_each(|(a, b)| *a += *b);
        let norm = |n: &Norm, x: &[f32]| {
            let mut out = vec![0.0_f32; x.len()];
            crate::kernels::layer_norm(x, &n.gamma, &n.beta, 1e-5, &mut out).unwrap();
            out
        };
        let mut h: Vec<Vec<f32>> = vec![
            naive_linear(&self.cond_in, condition),
            float.noise_token.clone(),
        ];
        add(&mut h[0], &float.positions[..w]);
        for i in 0..s.horizon {
            let mut token = naive_linear(
                &self.traj_in,
                &trajectory[i * s.action_dim..(i + 1) * s.action_dim],
            );
            add(&mut token, &float.positions[(2 + i) * w..(3 + i) * w]);
            h.push(token);
        }
        let scale = (1.0 / (hd as f64).sqrt()) as f32;
        for (q, f) in self.blocks.iter().zip(&float.blocks) {
            let qkv: Vec<Vec<f32>> = h
                .iter()
                .map(|x| naive_linear(&q.qkv, &norm(&f.norm1, x)))
                .collect();
            let mut attention = vec![vec![0_i8; w]; t];
            for head in 0..s.heads {
                let o = head * hd;
                for i in 0..t {
                    let mut scores: Vec<f32> = (0..t)
                        .map(|j| {
                            (0..hd).fold(0.0_f32, |acc, d| acc + qkv[i][o + d] * qkv[j][w + o + d])
                                * scale
                        })
                        .collect();
                    crate::kernels::softmax_in_place(&mut scores).unwrap();
                    for d in 0..hd {
                        let value =
                            (0..t).fold(0.0_f32, |acc, j| acc + scores[j] * qkv[j][2 * w + o + d]);
                        attention[i][o + d] = q.proj.input.quantize(value);
                    }
                }
            }
            for (x, codes) in h.iter_mut().zip(&attention) {
                let row: Vec<f32> = (0..w)
                    .map(|o| naive_accumulator(&q.proj, o, codes) as f32 * q.proj.output_scales[o])
                    .collect();
                add(x, &row);
                let codes: Vec<i8> = norm(&f.norm2, x)
                    .iter()
                    .map(|v| q.fc1.input.quantize(*v))
                    .collect();
                let hidden: Vec<i8> = (0..4 * w)
                    .map(|o| {
                        let pre = crate::quant::reference::requantize(
                            naive_accumulator(&q.fc1, o, &codes),
                            q.multipliers[o],
                            q.shifts[o],
                            q.fc1_output.zero_point,
                            -128,
                            127,
                        );
                        q.gelu.table[(i32::from(pre) + 128) as usize]
                    })
                    .collect();
                let row: Vec<f32> = (0..w)
                    .map(|o| naive_accumulator(&q.fc2, o, &hidden) as f32 * q.fc2.output_scales[o])
                    .collect();
                add(x, &row);
            }
        }
        let codes: Vec<i8> = h
            .iter()
            .flat_map(|x| norm(&float.final_norm, x))
            .map(|v| self.head.input.quantize(v))
            .collect();
        (0..s.output)
            .map(|o| naive_accumulator(&self.head, o, &codes) as f32 * self.head.output_scales[o])
            .collect()
    }
}
