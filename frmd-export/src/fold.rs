//! Folding a student checkpoint into the runtime's structure, in f32: per-step constants from the
//! sigma schedule, the noise embedding of each step folded into a first-layer bias variant, and
//! the input layout of the float model. The result ([`FoldedMlp`]) runs on frmd-core's own f32
//! path ([`frmd_core::model::mlp::F32Mlp`]) and is what calibration and quantization start from.
//!
//! The student is the consistency function of frmd-host (`diffusion/precond.rs`) in its
//! checkpoint's output parametrization: with the boundary skip, step i has the consistency
//! `c_skip(sigma_i)`, `c_out(sigma_i)` of frmd-core's `sigma` module and the runtime forms
//! `b + c_skip (x - b) + c_out (g - b)` ([`frmd_core::policy::skip_output`]); a direct-output
//! student has `c_skip = 0`, `c_out = 1`. Sampling levels are `consistency_sampling_sigma(i,
//! steps)`, re-noised with `sqrt(sigma_i^2 - sigma_min^2)` (frmd-host
//! `samplers::sample_consistency`).
//!
//! Input gains: the model input is quantized with one int8 scale for the whole vector, and the
//! `c_in`-scaled noisy trajectory (about +-4.5 at sigma_max) would otherwise set that scale for
//! the observations (+-1). [`FoldedMlp::with_input_gains`] multiplies the trajectory segment by
//! `traj_gain` (folded into every step's baked `c_in`) and the rate segment by `rate_gain` (folded
//! into the layout's `rate_scale`), and divides the matching first-layer weight columns by the
//! same gains, so the f32 function is unchanged while every segment spans about the same range.
//! The baked `c_in` is therefore `c_in(sigma) * traj_gain`.
use crate::checkpoint::{Activation, BackboneConfig, Checkpoint, ModelConfig, ProDmpOutput, Role};
use anyhow::{bail, Context};
use frmd_core::kernels::Activation as KernelActivation;
use frmd_core::model::linear::F32Linear;
use frmd_core::model::mlp::{F32Mlp, F32Scratch, Probe};
use frmd_core::policy::{
    skip_output, F32MlpNetwork, InputLayout, InputSegment, StepConstants, MAX_HIDDEN_LAYERS,
    MAX_STEPS,
};
use frmd_core::prodmp::{apply_row_f32, ProDmp, ProDmpConfig};
use frmd_core::sigma::{noise_embedding, SigmaConfig};

use crate::ProDmpTablesOwned;

/// Widest layer the exporter's f32 path (and the host int8 runners) handle.
pub const MAX_WIDTH: usize = 1024;

/// One f32 layer, row-major `[out, in]` weights.
#[derive(Clone, Debug, PartialEq)]
pub struct FloatLayer {
    pub in_features: usize,
    pub out_features: usize,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
    pub activation: KernelActivation,
}

impl FloatLayer {
    /// frmd-core's f32 layer over these weights with `bias`.
    pub fn view<'a>(&'a self, bias: &'a [f32]) -> F32Linear<'a> {
        F32Linear {
            in_features: self.in_features,
            out_features: self.out_features,
            weights: &self.weights,
            bias,
            activation: self.activation,
        }
    }
}

/// A student MLP folded for `steps` sampling steps.
#[derive(Clone, Debug)]
pub struct FoldedMlp {
    pub config: ModelConfig,
    pub sigma: SigmaConfig,
    /// Hidden layers; the first one's weights lack the embedding columns.
    pub hidden: Vec<FloatLayer>,
    pub output: FloatLayer,
    /// Per step: first hidden layer bias with `W_emb . embedding(c_noise(sigma_i))` added.
    pub first_layer_biases: Vec<Vec<f32>>,
    pub steps: Vec<StepConstants>,
    pub layout: InputLayout,
    pub prodmp: ProDmpTablesOwned,
    /// Input gains applied so far (1 after [`FoldedMlp::new`]).
    pub gains: InputGains,
}

/// Factors on the trajectory and rate input segments (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputGains {
    pub traj_gain: f32,
    pub rate_gain: f32,
}

impl Default for InputGains {
    fn default() -> Self {
        InputGains {
            traj_gain: 1.0,
            rate_gain: 1.0,
        }
    }
}

fn kernel_activation(a: Activation) -> KernelActivation {
    match a {
        Activation::Silu => KernelActivation::Silu,
        Activation::Mish => KernelActivation::Mish,
    }
}

/// The step table for `steps` (1..=4) sampling steps of a student with output parametrization
/// `output`.
pub fn step_constants(
    sigma: &SigmaConfig,
    output: ProDmpOutput,
    steps: usize,
) -> anyhow::Result<Vec<StepConstants>> {
    if !(1..=MAX_STEPS).contains(&steps) {
        bail!("the student samples with 1..={MAX_STEPS} steps, not {steps}");
    }
    let err = |what: &'static str| move |e| anyhow::anyhow!("{what}: {e:?}");
    (0..steps)
        .map(|i| {
            let level = sigma
                .consistency_sampling_sigma(i, steps)
                .map_err(err("sampling level"))?;
            let step = StepConstants::consistency(sigma, level, i as u32)
                .map_err(err("step constants"))?;
            Ok(match output {
                ProDmpOutput::Direct => StepConstants {
                    c_skip: 0.0,
                    c_out: 1.0,
                    ..step
                },
                ProDmpOutput::BoundarySkip => step,
            })
        })
        .collect()
}

/// The float MLP's input order: `[obs history, y0, v0 * control_dt, c_in x]` (the embedding,
/// which follows, is folded into the bias).
pub fn mlp_layout(config: &ModelConfig) -> anyhow::Result<InputLayout> {
    InputLayout::new(
        &[
            InputSegment::ObsHistory,
            InputSegment::PrevAction,
            InputSegment::PrevRate,
            InputSegment::NoisyTrajectory,
        ],
        config.control_dt as f32,
    )
    .map_err(|e| anyhow::anyhow!("input layout: {e}"))
}

impl ProDmpTablesOwned {
    /// Tables for `cfg` at the policy's query times `tau/n .. tau` (as
    /// [`frmd_core::prodmp::BakedProDmp::from_config`], for run-time sizes).
    pub fn from_config(cfg: &ProDmpConfig, horizon: usize) -> anyhow::Result<Self> {
        let decoder = ProDmp::new(cfg).map_err(|e| anyhow::anyhow!("ProDMP config: {e:?}"))?;
        let p = cfg.num_params_per_dof();
        let mut t = ProDmpTablesOwned {
            pos_params: vec![],
            vel_params: vec![],
            pos_y0: vec![],
            pos_v0: vec![],
            vel_y0: vec![],
            vel_v0: vec![],
        };
        for step in 1..=horizon {
            let time = step as f64 * (cfg.tau / horizon as f64);
            let (mut pos, mut vel) = (vec![0.0; p], vec![0.0; p]);
            let c = decoder
                .linear_row(0.0, time, &mut pos, &mut vel)
                .map_err(|e| anyhow::anyhow!("ProDMP row {step}: {e:?}"))?;
            t.pos_params.extend(pos.iter().map(|&v| v as f32));
            t.vel_params.extend(vel.iter().map(|&v| v as f32));
            t.pos_y0.push(c.pos_y0 as f32);
            t.pos_v0.push(c.pos_v0 as f32);
            t.vel_y0.push(c.vel_y0 as f32);
            t.vel_v0.push(c.vel_v0 as f32);
        }
        Ok(t)
    }

    /// The initial-condition part `[n][k]` of every chunk (the decode of all-zero parameters),
    /// rounded as the firmware rounds it ([`frmd_core::prodmp::BoundaryRow::at`]).
    pub fn boundary_positions(&self, y0: &[f32], v0: &[f32]) -> Vec<f32> {
        let rows = self.pos_y0.iter().zip(&self.pos_v0);
        rows.flat_map(|(&pos_y0, &pos_v0)| {
            y0.iter()
                .zip(v0)
                .map(move |(&y, &v)| apply_row_f32(&[], pos_y0, pos_v0, &[], y, v))
        })
        .collect()
    }

    /// Decoded positions `[n][k]` (step-major) of DoF-major `params`, with
    /// [`frmd_core::prodmp::apply_row_f32`] (the firmware's rounding).
    pub fn decode_positions(&self, params: &[f32], y0: &[f32], v0: &[f32]) -> Vec<f32> {
        let n = self.pos_y0.len();
        let k = y0.len();
        let p = self.pos_params.len() / n.max(1);
        let mut out = Vec::with_capacity(n * k);
        for t in 0..n {
            let row = &self.pos_params[t * p..(t + 1) * p];
            for d in 0..k {
                out.push(apply_row_f32(
                    row,
                    self.pos_y0[t],
                    self.pos_v0[t],
                    &params[d * p..(d + 1) * p],
                    y0[d],
                    v0[d],
                ));
            }
        }
        out
    }
}

impl FoldedMlp {
    /// Folds a student MLP checkpoint for `steps` sampling steps, refusing what the runtime
    /// cannot represent.
    pub fn new(ckpt: &Checkpoint, steps: usize) -> anyhow::Result<Self> {
        let meta = &ckpt.meta;
        let config = &meta.model;
        if meta.role != Role::Student {
            bail!("only student checkpoints can be exported; this one is a {:?} (its sampler needs many network evaluations)", meta.role);
        }
        let (hidden_sizes, activation) = match &config.backbone {
            BackboneConfig::Mlp { hidden, activation } => (hidden.clone(), *activation),
            BackboneConfig::Transformer { .. } => bail!(
                "transformer backbones fold with transformer::FoldedTransformer (export::export_transformer_checkpoint); the MLP blob/baked formats cannot hold them"
            ),
        };
        if hidden_sizes.len() > MAX_HIDDEN_LAYERS {
            bail!(
                "{} hidden layers exceed the runtime limit of {MAX_HIDDEN_LAYERS}",
                hidden_sizes.len()
            );
        }
        let prodmp_cfg = config.prodmp().context("a student needs a ProDMP head")?;
        let layout = mlp_layout(config)?;
        let input_width = layout
            .width(
                config.history,
                config.obs_dim,
                config.action_dim,
                config.horizon,
            )
            .context("input width overflows")?;
        let widest = hidden_sizes
            .iter()
            .copied()
            .chain([input_width, config.output_dim()])
            .max()
            .unwrap_or(0);
        if widest > MAX_WIDTH {
            bail!("layer width {widest} exceeds the exporter's limit of {MAX_WIDTH}");
        }
        let sigma: SigmaConfig = meta.sigma;
        let steps = step_constants(
            &sigma,
            meta.model.prodmp_output().unwrap_or_default(),
            steps,
        )?;
        let mut layers = Vec::new();
        let mut width = input_width + config.embed_dim;
        for (i, &out) in hidden_sizes
            .iter()
            .chain([&config.output_dim()])
            .enumerate()
        {
            let weights = ckpt.tensor(&format!("mlp.layers.{i}.weight"))?.to_vec();
            let bias = ckpt.tensor(&format!("mlp.layers.{i}.bias"))?.to_vec();
            let act = if i < hidden_sizes.len() {
                kernel_activation(activation)
            } else {
                KernelActivation::Identity
            };
            layers.push(FloatLayer {
                in_features: width,
                out_features: out,
                weights,
                bias,
                activation: act,
            });
            width = out;
        }
        let output = layers.pop().context("internal: no output layer")?;
        let mut hidden = layers;
        let first = hidden
            .first_mut()
            .context("a student MLP has at least one hidden layer")?;
        // Split the first layer's columns: [input | embedding].
        let full_in = first.in_features;
        let mut embedding = vec![0.0f64; config.embed_dim];
        let mut first_layer_biases = Vec::new();
        for i in 0..steps.len() {
            let level = sigma
                .consistency_sampling_sigma(i, steps.len())
                .map_err(|e| anyhow::anyhow!("sampling level: {e:?}"))?;
            let c_noise = sigma
                .c_noise(level)
                .map_err(|e| anyhow::anyhow!("c_noise: {e:?}"))?;
            noise_embedding(c_noise, &mut embedding)
                .map_err(|e| anyhow::anyhow!("noise embedding: {e:?}"))?;
            let bias: Vec<f32> = (0..first.out_features)
                .map(|o| {
                    let row = &first.weights[o * full_in + input_width..(o + 1) * full_in];
                    let folded: f64 = row
                        .iter()
                        .zip(&embedding)
                        .map(|(w, e)| f64::from(*w) * ((*e as f32) as f64))
                        .sum();
                    (f64::from(first.bias[o]) + folded) as f32
                })
                .collect();
            first_layer_biases.push(bias);
        }
        first.weights = first
            .weights
            .chunks_exact(full_in)
            .flat_map(|row| row[..input_width].iter().copied())
            .collect();
        first.in_features = input_width;
        first.bias = first_layer_biases[0].clone();
        Ok(FoldedMlp {
            config: config.clone(),
            sigma,
            hidden,
            output,
            first_layer_biases,
            steps,
            layout,
            prodmp: ProDmpTablesOwned::from_config(&prodmp_cfg, config.horizon)?,
            gains: InputGains::default(),
        })
    }

    /// The same function with the trajectory and rate input segments scaled by `gains` (relative
    /// to the current ones) and the first layer's matching columns divided by them.
    pub fn with_input_gains(&self, gains: InputGains) -> anyhow::Result<Self> {
        let (traj, rate) = (gains.traj_gain, gains.rate_gain);
        if !(traj.is_finite() && traj > 0.0 && rate.is_finite() && rate > 0.0) {
            bail!("input gains must be finite and positive, got {gains:?}");
        }
        let c = &self.config;
        let (obs_len, k) = (c.history * c.obs_dim, c.action_dim);
        let mut out = self.clone();
        let first = out
            .hidden
            .first_mut()
            .context("a student MLP has at least one hidden layer")?;
        let width = first.in_features;
        for row in first.weights.chunks_exact_mut(width) {
            for (i, w) in row.iter_mut().enumerate() {
                if i >= obs_len + 2 * k {
                    *w /= traj;
                } else if i >= obs_len + k {
                    *w /= rate;
                }
            }
        }
        for step in &mut out.steps {
            step.c_in *= traj;
        }
        out.layout.rate_scale *= rate;
        out.gains = InputGains {
            traj_gain: self.gains.traj_gain * traj,
            rate_gain: self.gains.rate_gain * rate,
        };
        Ok(out)
    }

    /// All first-layer bias variants back to back (the layout [`F32MlpNetwork`] takes).
    pub fn flat_first_layer_biases(&self) -> Vec<f32> {
        self.first_layer_biases.concat()
    }

    /// frmd-core's [`F32MlpNetwork`] over these weights, with `biases` from
    /// [`Self::flat_first_layer_biases`] (the f32 twin of the int8 network, for the runtime's
    /// own sampler and policy).
    pub fn f32_network<'a, const WIDTH: usize>(
        &'a self,
        biases: &'a [f32],
    ) -> anyhow::Result<F32MlpNetwork<'a, WIDTH>> {
        let views: Vec<F32Linear<'a>> = self.hidden.iter().map(|l| l.view(&l.bias)).collect();
        F32MlpNetwork::new(&views, self.output.view(&self.output.bias), biases)
            .map_err(|e| anyhow::anyhow!("f32 network: {e}"))
    }

    /// Input width of the folded network.
    pub fn input_width(&self) -> usize {
        self.hidden
            .first()
            .map_or(self.output.in_features, |l| l.in_features)
    }

    /// Runs step `step`'s network on `input` through frmd-core's f32 path, reporting every
    /// probe to `observe`; returns the `K * P` ProDMP parameters.
    pub fn forward_observed(
        &self,
        step: usize,
        input: &[f32],
        mut observe: impl FnMut(Probe, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        let bias = self
            .first_layer_biases
            .get(step)
            .context("step index out of range")?;
        let views: Vec<F32Linear<'_>> = self
            .hidden
            .iter()
            .enumerate()
            .map(|(i, l)| l.view(if i == 0 { bias } else { &l.bias }))
            .collect();
        let mlp = F32Mlp {
            hidden: &views,
            output: self.output.view(&self.output.bias),
        };
        let mut scratch = Box::new(F32Scratch::<MAX_WIDTH>::new());
        let mut out = vec![0.0; self.output.out_features];
        mlp.forward_observed(input, &mut out, &mut scratch, &mut observe)
            .map_err(|e| anyhow::anyhow!("f32 forward: {e}"))?;
        Ok(out)
    }

    /// Builds the model input of one step (see [`model_input`]).
    pub fn input(&self, step: &StepConstants, cond: &[f32], x: &[f32]) -> anyhow::Result<Vec<f32>> {
        model_input(&self.config, &self.layout, step, cond, x)
    }

    /// The f32 consistency sampler over all steps with the given standard-normal `noise`
    /// (`steps * n * k` values): returns the chunk positions (normalized, `[n][k]`), calling
    /// `observe(step, probe, values)` for every probe of every step.
    pub fn sample(
        &self,
        cond: &[f32],
        noise: &[f32],
        mut observe: impl FnMut(usize, Probe, &[f32]),
    ) -> anyhow::Result<Vec<f32>> {
        sample_chunk(
            &self.config,
            &self.layout,
            &self.steps,
            &self.prodmp,
            cond,
            noise,
            |i, input| self.forward_observed(i, input, |p, v| observe(i, p, v)),
        )
    }
}

/// Builds the model input of one step in the standard layout: `cond = [obs history, y0, v0]`
/// (normalized, v0 per second) and the unscaled noisy trajectory `x` (`[n][k]`) become
/// `[obs history, y0, v0 * rate_scale, c_in x]`.
pub fn model_input(
    config: &ModelConfig,
    layout: &InputLayout,
    step: &StepConstants,
    cond: &[f32],
    x: &[f32],
) -> anyhow::Result<Vec<f32>> {
    let c = config;
    let obs_len = c.history * c.obs_dim;
    let k = c.action_dim;
    if cond.len() != c.cond_dim() || x.len() != c.traj_dim() {
        bail!(
            "model input: condition has {} values (expected {}), trajectory {} (expected {})",
            cond.len(),
            c.cond_dim(),
            x.len(),
            c.traj_dim()
        );
    }
    let mut input = Vec::with_capacity(c.cond_dim() + c.traj_dim());
    input.extend_from_slice(&cond[..obs_len + k]);
    input.extend(
        cond[obs_len + k..obs_len + 2 * k]
            .iter()
            .map(|v| v * layout.rate_scale),
    );
    input.extend(x.iter().map(|v| step.c_in * v));
    Ok(input)
}

/// The host consistency sampler over all `steps` with standard-normal `noise` (`steps * n * k`
/// values), for any network: `forward(step_index, model_input)` returns the `K * P` ProDMP
/// parameters. Returns the chunk positions (normalized, `[n][k]`).
pub fn sample_chunk(
    config: &ModelConfig,
    layout: &InputLayout,
    steps: &[StepConstants],
    prodmp: &ProDmpTablesOwned,
    cond: &[f32],
    noise: &[f32],
    mut forward: impl FnMut(usize, &[f32]) -> anyhow::Result<Vec<f32>>,
) -> anyhow::Result<Vec<f32>> {
    let c = config;
    let (k, traj) = (c.action_dim, c.traj_dim());
    let obs_len = c.history * c.obs_dim;
    if cond.len() != obs_len + 2 * k || noise.len() < steps.len() * traj {
        bail!(
            "condition has {} values (expected {}), noise {} (expected {})",
            cond.len(),
            obs_len + 2 * k,
            noise.len(),
            steps.len() * traj
        );
    }
    let (y0, v0) = (&cond[obs_len..obs_len + k], &cond[obs_len + k..]);
    let boundary = prodmp.boundary_positions(y0, v0);
    let mut f = vec![0.0f32; traj];
    for (i, step) in steps.iter().enumerate() {
        let z = &noise[i * traj..(i + 1) * traj];
        let x: Vec<f32> = if i == 0 {
            z.iter().map(|z| step.sigma * z).collect()
        } else {
            f.iter()
                .zip(z)
                .map(|(f, z)| f + step.renoise_std * z)
                .collect()
        };
        let input = model_input(config, layout, step, cond, &x)?;
        let params = forward(i, &input)?;
        let decoded = prodmp.decode_positions(&params, y0, v0);
        f = x
            .iter()
            .zip(&decoded)
            .zip(&boundary)
            .map(|((&x, &g), &b)| skip_output(step.c_skip, step.c_out, x, g, b))
            .collect();
    }
    Ok(f)
}
