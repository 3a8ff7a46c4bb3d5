//! The f32 network of a folded MLP with chosen quantization sources simulated ("fake
//! quantization": quantize and dequantize in f32), and a closed-loop policy over it.
use frmd_core::quant::{quantize_weights_per_channel, QuantParams};
use frmd_core::rng::Rng;
use frmd_export::mlp::{FoldedMlp, Ranges};
use frmd_formats::checkpoint::Normalization;

/// Which quantization sources are simulated.
#[derive(Clone, Copy, Default)]
pub struct Sources {
    pub input: bool,
    pub hidden_weights: bool,
    pub output_weights: bool,
    pub pre_activation: bool,
    pub post_activation: bool,
    /// Clip the pre-activation range's negative end at `-clip` (0: no clip).
    pub clip: f32,
    /// Activation resolution multiplier (1 = int8; 256 = int16-like).
    pub fine: f32,
    /// Pre-activation resolution multiplier when it differs from `fine` (0: use `fine`): a wider
    /// activation-table index with int8 table outputs, e.g. 4 = a 10-bit pre-activation code.
    pub pre_fine: f32,
    /// Input treatment when `input` is off: 0 exact, 1 clamp to the int8 range only, 2 round
    /// only (no clamp), 3 two-plane-like (clamp, 1/256 steps).
    pub input_mode: u8,
}

fn fake(x: f32, q: QuantParams) -> f32 {
    q.dequantize(q.quantize(x))
}

fn fake_fine(x: f32, q: QuantParams, fine: f32) -> f32 {
    if fine <= 1.0 {
        return fake(x, q);
    }
    let lo = q.dequantize(i8::MIN);
    let hi = q.dequantize(i8::MAX);
    let s = q.scale / fine;
    ((x.clamp(lo, hi)) / s).round() * s
}

fn fake_weights(w: &[f32], in_features: usize) -> Vec<f32> {
    let out = w.len() / in_features;
    let (mut q, mut s) = (vec![0i8; w.len()], vec![0f32; out]);
    quantize_weights_per_channel(w, in_features, &mut q, &mut s).expect("weights");
    q.iter()
        .enumerate()
        .map(|(i, &v)| f32::from(v) * s[i / in_features])
        .collect()
}

pub struct Sim<'a> {
    pub folded: &'a FoldedMlp,
    ranges: &'a Ranges,
    src: Sources,
    hidden_w: Vec<Vec<f32>>,
    output_w: Vec<f32>,
}

impl<'a> Sim<'a> {
    pub fn new(folded: &'a FoldedMlp, ranges: &'a Ranges, src: Sources) -> Self {
        let hidden_w = folded
            .hidden
            .iter()
            .map(|l| {
                if src.hidden_weights {
                    fake_weights(&l.weights, l.in_features)
                } else {
                    l.weights.clone()
                }
            })
            .collect();
        let o = &folded.output;
        let output_w = if src.output_weights {
            fake_weights(&o.weights, o.in_features)
        } else {
            o.weights.clone()
        };
        Sim {
            folded,
            ranges,
            src,
            hidden_w,
            output_w,
        }
    }

    pub fn forward(&self, step: usize, input: &[f32]) -> Vec<f32> {
        let q = self.ranges.input;
        let (lo, hi) = (q.dequantize(i8::MIN), q.dequantize(i8::MAX));
        let c = &self.folded.base.config;
        let (obs_len, k) = (c.history * c.obs_dim, c.action_dim);
        let segment = |i: usize| {
            if i < obs_len {
                4
            } else if i < obs_len + k {
                5
            } else if i < obs_len + 2 * k {
                6
            } else {
                7
            }
        };
        let mut x: Vec<f32> = input
            .iter()
            .enumerate()
            .map(|(i, &v)| match (self.src.input, self.src.input_mode) {
                (true, _) => fake(v, q),
                (false, 1) => v.clamp(lo, hi),
                (false, m @ 4..=7) if segment(i) == m => v.clamp(lo, hi),
                (false, 2) => ((v / q.scale).round()) * q.scale,
                (false, 3) => {
                    let h: f32 = std::env::var("HEADROOM")
                        .ok()
                        .and_then(|h| h.parse().ok())
                        .unwrap_or(1.0);
                    fake_fine(v, QuantParams::from_range(lo * h, hi * h).unwrap(), 256.0)
                }
                _ => v,
            })
            .collect();
        let pre_fine = if self.src.pre_fine > 0.0 {
            self.src.pre_fine
        } else {
            self.src.fine
        };
        for (l, layer) in self.folded.hidden.iter().enumerate() {
            let bias = if l == 0 {
                &self.folded.first_layer_biases[step]
            } else {
                &layer.bias
            };
            let (mut pre_q, mut out_q) = self.ranges.hidden[l];
            let a: f32 = std::env::var("ACT_HEADROOM")
                .ok()
                .and_then(|h| h.parse().ok())
                .unwrap_or(1.0);
            if a != 1.0 {
                let widen = |q: QuantParams| {
                    QuantParams::from_range(q.dequantize(i8::MIN) * a, q.dequantize(i8::MAX) * a)
                        .unwrap()
                };
                pre_q = widen(pre_q);
                out_q = widen(out_q);
            }
            if self.src.clip > 0.0 {
                let hi = pre_q.dequantize(i8::MAX);
                let lo = pre_q.dequantize(i8::MIN).max(-self.src.clip);
                pre_q = QuantParams::from_range(lo, hi).unwrap();
            }
            x = (0..layer.out_features)
                .map(|o| {
                    let row = &self.hidden_w[l][o * layer.in_features..(o + 1) * layer.in_features];
                    let mut pre = row.iter().zip(&x).fold(bias[o], |a, (w, v)| a + w * v);
                    if self.src.pre_activation {
                        pre = fake_fine(pre, pre_q, pre_fine);
                    }
                    let y = layer.activation.apply(pre);
                    if self.src.post_activation {
                        fake_fine(y, out_q, self.src.fine)
                    } else {
                        y
                    }
                })
                .collect();
        }
        let o = &self.folded.output;
        (0..o.out_features)
            .map(|r| {
                self.output_w[r * o.in_features..(r + 1) * o.in_features]
                    .iter()
                    .zip(&x)
                    .fold(o.bias[r], |a, (w, v)| a + w * v)
            })
            .collect()
    }
}

pub struct SimPolicy<'a> {
    pub sim: &'a Sim<'a>,
    pub norm: &'a Normalization,
    pub rng: Rng,
}

impl frmd_host::tasks::Policy for SimPolicy<'_> {
    fn name(&self) -> String {
        "sim".into()
    }
    fn reset(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
    }
    fn act(&mut self, input: &frmd_host::tasks::PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let folded = self.sim.folded;
        let c = &folded.base.config;
        let mut cond = Vec::new();
        for o in input.obs_history {
            let mut o = o.to_vec();
            self.norm.obs.normalize(&mut o);
            if std::env::var_os("OBS_STATS").is_some() {
                let m = o.iter().fold(0f32, |a, v| a.max(v.abs()));
                OBS_HIST.with(|h| {
                    let mut h = h.borrow_mut();
                    for (i, t) in [1.0f32, 1.05, 1.25, 1.5, 2.0, 3.0, 4.0].iter().enumerate() {
                        if m > *t {
                            h[i] += 1;
                        }
                    }
                    h[7] += 1;
                    h[8] = h[8].max((m * 1000.0) as usize);
                });
            }
            cond.extend(o);
        }
        let mut prev = input.prev_action.to_vec();
        self.norm.action.normalize(&mut prev);
        cond.extend(prev);
        cond.extend(
            input
                .prev_rate
                .iter()
                .zip(self.norm.action.scale())
                .map(|(r, s)| r * s),
        );
        let mut noise = vec![0f32; folded.base.steps.len() * c.traj_dim()];
        self.rng.fill_gaussian(&mut noise);
        let mut chunk = folded
            .base
            .sample(&cond, &noise, |i, x| Ok(self.sim.forward(i, x)))?;
        self.norm.action.denormalize(&mut chunk);
        Ok(chunk.chunks(c.action_dim).map(|a| a.to_vec()).collect())
    }
}

thread_local! {
    static OBS_HIST: std::cell::RefCell<[usize; 9]> = const { std::cell::RefCell::new([0; 9]) };
}

/// Closed-loop observation counts: above 1, 1.05, 1.25, 1.5, 2, 3, 4 (normalized); total;
/// max x 1000.
pub fn obs_stats() -> [usize; 9] {
    OBS_HIST.with(|h| *h.borrow())
}
