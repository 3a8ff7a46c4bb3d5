//! Where does the int8 student's error come from? Exports a student (as `frmd export`), then runs
//! the f32 sampler of the folded network with one quantization source switched on at a time
//! ("fake quantization": the value is quantized and dequantized in f32) and reports the chunk
//! error against the exact f32 path in action units; the last line is frmd-core's real int8
//! network on the same inputs.
//!
//! `cargo run -p frmd-host --example int8_breakdown -- CKPT DATA [ROWS] [CALIBRATION]`
//!
//! Environment: `EPISODES=n` also runs every variant closed loop on the checkpoint's task (the
//! f32 sampler with the variant's fake quantization; `VARIANTS=a;b` picks variants by label);
//! `HEADROOM` / `ACT_HEADROOM` widen the simulated input / activation ranges; `OBS_STATS=1`
//! prints how far closed-loop observations leave the training range; `INT8_INPUT=1` and
//! `EXPORT_HEADROOM` set the export options of the "real int8" line.
use anyhow::Context;
use frmd_core::policy::Network;
use frmd_core::quant::{quantize_weights_per_channel, QuantParams};
use frmd_core::rng::Rng;
use frmd_export::calibrate::RangeMethod;
use frmd_export::export::{export_checkpoint, ExportOptions};
use frmd_export::fold::{sample_chunk, FoldedMlp, MAX_WIDTH};
use std::path::Path;

/// Which quantization sources are simulated.
#[derive(Clone, Copy, Default)]
struct Sources {
    input: bool,
    hidden_weights: bool,
    output_weights: bool,
    pre_activation: bool,
    post_activation: bool,
    /// Clip the pre-activation range's negative end at `-clip` (0: no clip).
    clip: f32,
    /// Activation resolution multiplier (1 = int8; 256 = int16-like).
    fine: f32,
    /// Pre-activation resolution multiplier when it differs from `fine` (0: use `fine`): a wider
    /// activation-table index with int8 table outputs, e.g. 4 = a 10-bit pre-activation code.
    pre_fine: f32,
    /// Input treatment when `input` is off: 0 exact, 1 clamp to the int8 range only, 2 round
    /// only (no clamp), 3 two-plane-like (clamp, 1/256 steps).
    input_mode: u8,
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

struct Sim<'a> {
    folded: &'a FoldedMlp,
    ranges: &'a frmd_export::calibrate::Ranges,
    src: Sources,
    hidden_w: Vec<Vec<f32>>,
    output_w: Vec<f32>,
}

impl<'a> Sim<'a> {
    fn new(
        folded: &'a FoldedMlp,
        ranges: &'a frmd_export::calibrate::Ranges,
        src: Sources,
    ) -> Self {
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

    fn forward(&self, step: usize, input: &[f32]) -> Vec<f32> {
        let q = self.ranges.input;
        let (lo, hi) = (q.dequantize(i8::MIN), q.dequantize(i8::MAX));
        let c = &self.folded.config;
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

/// One network evaluation: (step, model input) -> network output.
type Forward<'a> = Box<dyn FnMut(usize, &[f32]) -> anyhow::Result<Vec<f32>> + 'a>;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let ckpt = Path::new(args.get(1).context("CKPT")?);
    let data = Path::new(args.get(2).context("DATA")?);
    let rows: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(200);
    let ranges: RangeMethod = args
        .get(4)
        .map(String::as_str)
        .unwrap_or("minmax")
        .parse()?;
    let set = frmd_host::export::calibration_from_data(data, ckpt)?;
    let exported = export_checkpoint(
        ckpt,
        ExportOptions {
            ranges,
            input_precision: if std::env::var_os("INT8_INPUT").is_none() {
                frmd_core::model::mlp::InputPrecision::Int16
            } else {
                frmd_core::model::mlp::InputPrecision::Int8
            },
            input_headroom: std::env::var("EXPORT_HEADROOM")
                .ok()
                .and_then(|h| h.parse().ok())
                .unwrap_or(frmd_export::export::DEFAULT_INPUT_HEADROOM),
            ..ExportOptions::default()
        },
        Some(set.clone()),
    )?;
    let folded = &exported.folded;
    let c = &folded.config;
    let norm = exported
        .checkpoint
        .meta
        .normalization
        .clone()
        .context("normalization")?;
    let traj = c.traj_dim();
    let steps = folded.steps.len();
    let rows = rows.min(set.rows());
    println!("input {:?}", exported.ranges.input);
    for (l, (p, o)) in exported.ranges.hidden.iter().enumerate() {
        println!("layer {l}: pre {p:?} out {o:?}");
    }
    let run = |label: &str, mut forward: Forward<'_>| -> anyhow::Result<()> {
        let (mut max_e, mut sum_e, mut n, mut max_p, mut sum_p, mut signed) =
            (0f64, 0f64, 0usize, 0f64, 0f64, 0f64);
        for r in 0..rows {
            let cond = &set.cond[r * set.cond_dim..(r + 1) * set.cond_dim];
            let mut noise = vec![0f32; steps * traj];
            Rng::new(0xe901_0000 + r as u64).fill_gaussian(&mut noise);
            let mut exact_params = Vec::new();
            let mut exact = sample_chunk(
                c,
                &folded.layout,
                &folded.steps,
                &folded.prodmp,
                cond,
                &noise,
                |i, input| {
                    let p = folded.forward_observed(i, input, |_, _| {})?;
                    exact_params = p.clone();
                    Ok(p)
                },
            )?;
            let mut got_params = Vec::new();
            let mut got = sample_chunk(
                c,
                &folded.layout,
                &folded.steps,
                &folded.prodmp,
                cond,
                &noise,
                |i, input| {
                    let p = forward(i, input)?;
                    got_params = p.clone();
                    Ok(p)
                },
            )?;
            norm.action.denormalize(&mut exact);
            norm.action.denormalize(&mut got);
            for (a, b) in exact.iter().zip(&got) {
                let e = f64::from((a - b).abs());
                signed += f64::from(b - a);
                max_e = max_e.max(e);
                sum_e += e;
                n += 1;
            }
            for (a, b) in exact_params.iter().zip(&got_params) {
                let e = f64::from((a - b).abs());
                max_p = max_p.max(e);
                sum_p += e;
            }
        }
        let np = (rows * exact_params_len(folded)) as f64;
        println!("{label:<28} chunk max {max_e:.5} mean {:.6} signed {:+.6} (action units) | params max {max_p:.5} mean {:.6}", sum_e / n as f64, signed / n as f64, sum_p / np);
        Ok(())
    };
    let all = Sources {
        input: true,
        hidden_weights: true,
        output_weights: true,
        pre_activation: true,
        post_activation: true,
        clip: 0.0,
        fine: 1.0,
        pre_fine: 0.0,
        input_mode: 0,
    };
    let variants: [(&str, Sources); 27] = [
        (
            "activations only, int16-like",
            Sources {
                pre_activation: true,
                post_activation: true,
                fine: 256.0,
                ..Default::default()
            },
        ),
        (
            "activations only, 2^-16 of int16",
            Sources {
                pre_activation: true,
                post_activation: true,
                fine: 16_777_216.0,
                ..Default::default()
            },
        ),
        (
            "all, two-plane input",
            Sources {
                input: false,
                input_mode: 3,
                ..all
            },
        ),
        (
            "clamp obs",
            Sources {
                input_mode: 4,
                ..Default::default()
            },
        ),
        (
            "clamp prev action",
            Sources {
                input_mode: 5,
                ..Default::default()
            },
        ),
        (
            "clamp rate",
            Sources {
                input_mode: 6,
                ..Default::default()
            },
        ),
        (
            "clamp trajectory",
            Sources {
                input_mode: 7,
                ..Default::default()
            },
        ),
        (
            "input clamp only",
            Sources {
                input_mode: 1,
                ..Default::default()
            },
        ),
        (
            "input rounding only",
            Sources {
                input_mode: 2,
                ..Default::default()
            },
        ),
        (
            "input two-plane-like",
            Sources {
                input_mode: 3,
                ..Default::default()
            },
        ),
        ("none (sanity)", Sources::default()),
        (
            "input",
            Sources {
                input: true,
                ..Default::default()
            },
        ),
        (
            "hidden weights",
            Sources {
                hidden_weights: true,
                ..Default::default()
            },
        ),
        (
            "output weights",
            Sources {
                output_weights: true,
                ..Default::default()
            },
        ),
        (
            "pre-activation (requant)",
            Sources {
                pre_activation: true,
                ..Default::default()
            },
        ),
        (
            "post-activation (LUT out)",
            Sources {
                post_activation: true,
                ..Default::default()
            },
        ),
        (
            "activations (pre+post)",
            Sources {
                pre_activation: true,
                post_activation: true,
                ..Default::default()
            },
        ),
        ("all", all),
        (
            "all but input (int16-like input)",
            Sources {
                input: false,
                ..all
            },
        ),
        (
            "all but input, pre clip 6",
            Sources {
                input: false,
                clip: 6.0,
                ..all
            },
        ),
        (
            "all but pre (wide LUT)",
            Sources {
                pre_activation: false,
                ..all
            },
        ),
        (
            "all, int16-like activations",
            Sources { fine: 256.0, ..all },
        ),
        (
            "int16 act + exact input",
            Sources {
                fine: 256.0,
                input: false,
                ..all
            },
        ),
        (
            "all, 10-bit pre-activation",
            Sources {
                pre_fine: 4.0,
                ..all
            },
        ),
        (
            "all, 12-bit pre-activation",
            Sources {
                pre_fine: 16.0,
                ..all
            },
        ),
        (
            "all, 16-bit pre-activation",
            Sources {
                pre_fine: 256.0,
                ..all
            },
        ),
        (
            "two-plane input, int16 act",
            Sources {
                input: false,
                input_mode: 3,
                fine: 256.0,
                ..all
            },
        ),
    ];
    let closed_loop = std::env::var("EPISODES")
        .ok()
        .map(|e| e.parse::<usize>())
        .transpose()?
        .unwrap_or(0);
    if closed_loop > 0 {
        let task = exported.checkpoint.meta.dataset.task.clone();
        let eval = frmd_host::eval::EvalConfig {
            episodes: closed_loop,
            history: c.history,
            ..Default::default()
        };
        let only: Option<Vec<String>> = std::env::var("VARIANTS")
            .ok()
            .map(|v| v.split(';').map(String::from).collect());
        for (label, src) in variants
            .iter()
            .filter(|(l, _)| only.as_ref().is_none_or(|o| o.iter().any(|x| x == l)))
        {
            let sim = Sim::new(folded, &exported.ranges, *src);
            let mut policy = SimPolicy {
                sim: &sim,
                norm: &norm,
                rng: Rng::new(0),
            };
            let report = frmd_host::eval::run_episodes(&task, &mut policy, &eval)?;
            println!(
                "closed loop {label:<28} {task} {closed_loop} episodes: success {:.1} %",
                100.0 * report.success_rate
            );
            if std::env::var_os("OBS_STATS").is_some() {
                println!("  observations (normalized, max |.| per observation) above 1, 1.05, 1.25, 1.5, 2, 3, 4; total; max*1000: {:?}", obs_stats());
            }
        }
        return Ok(());
    }
    for (label, src) in variants {
        let sim = Sim::new(folded, &exported.ranges, src);
        run(label, Box::new(move |i, input| Ok(sim.forward(i, input))))?;
    }
    let mut net = Box::new(frmd_export::reference::int8_network::<MAX_WIDTH>(
        &exported.policy,
    )?);
    run(
        "real int8 (frmd-core)",
        Box::new(move |i, input| {
            let mut out = vec![0f32; net.output_width()];
            net.forward(i, input, &mut out)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok(out)
        }),
    )?;
    Ok(())
}

fn exact_params_len(folded: &FoldedMlp) -> usize {
    folded.output.out_features
}

struct SimPolicy<'a> {
    sim: &'a Sim<'a>,
    norm: &'a frmd_export::checkpoint::Normalization,
    rng: Rng,
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
        let c = &folded.config;
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
        let mut noise = vec![0f32; folded.steps.len() * c.traj_dim()];
        self.rng.fill_gaussian(&mut noise);
        let mut chunk = sample_chunk(
            c,
            &folded.layout,
            &folded.steps,
            &folded.prodmp,
            &cond,
            &noise,
            |i, x| Ok(self.sim.forward(i, x)),
        )?;
        self.norm.action.denormalize(&mut chunk);
        Ok(chunk.chunks(c.action_dim).map(|a| a.to_vec()).collect())
    }
}

thread_local! {
    static OBS_HIST: std::cell::RefCell<[usize; 9]> = const { std::cell::RefCell::new([0; 9]) };
}

#[allow(dead_code)]
fn obs_stats() -> [usize; 9] {
    OBS_HIST.with(|h| *h.borrow())
}
