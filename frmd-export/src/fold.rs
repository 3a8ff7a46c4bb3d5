//! Folding shared by both backbones, in f32: the step table from the sigma schedule, the noise
//! embedding of every sampling step (which each backbone folds into its network: the MLP's
//! first-layer bias, the transformer's noise token), the float models' input layout, the baked
//! ProDMP decoder tables and the host consistency sampler over any folded network.
//!
//! The student is the consistency function of frmd-host (`diffusion/precond.rs`) in its
//! checkpoint's output parametrization: with the boundary skip, step i has the consistency
//! `c_skip(sigma_i)`, `c_out(sigma_i)` of frmd-core's `sigma` module and the runtime forms
//! `b + c_skip (x - b) + c_out (g - b)` ([`frmd_core::policy::skip_output`]); a direct-output
//! student has `c_skip = 0`, `c_out = 1`. Sampling levels are `consistency_sampling_sigma(i,
//! steps)`, re-noised with `sqrt(sigma_i^2 - sigma_min^2)` (frmd-host
//! `samplers::sample_consistency`).
use anyhow::{bail, Context};
use frmd_core::kernels::Activation as KernelActivation;
use frmd_core::model::linear::F32Linear;
use frmd_core::policy::{
    skip_output, InputLayout, InputSegment, ProDmpTables, StepConstants, MAX_STEPS,
};
use frmd_core::prodmp::{apply_row_f32, BakedProDmp, ProDmp, ProDmpConfig};
use frmd_core::sigma::{noise_embedding, SigmaConfig};
use frmd_formats::checkpoint::{CheckpointMeta, ModelConfig, ProDmpOutput, Role};

/// One f32 layer, row-major `[out, in]` weights.
#[derive(Clone, Debug, PartialEq)]
pub struct FloatLayer {
    /// Input width.
    pub in_features: usize,
    /// Output width.
    pub out_features: usize,
    /// `[out, in]` weights.
    pub weights: Vec<f32>,
    /// `[out]` bias.
    pub bias: Vec<f32>,
    /// Activation after the bias.
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

/// ProDMP decoder tables (row-major `[N][P]` and `[N]`), as [`BakedProDmp`] holds them.
#[derive(Clone, Debug, PartialEq)]
pub struct ProDmpTablesOwned {
    /// `[N][P]` position coefficients of `[w.., g]`.
    pub pos_params: Vec<f32>,
    /// `[N][P]` velocity coefficients (1/s).
    pub vel_params: Vec<f32>,
    /// `[N]` position coefficient of `y0`.
    pub pos_y0: Vec<f32>,
    /// `[N]` position coefficient of `v0` (s).
    pub pos_v0: Vec<f32>,
    /// `[N]` velocity coefficient of `y0` (1/s).
    pub vel_y0: Vec<f32>,
    /// `[N]` velocity coefficient of `v0`.
    pub vel_v0: Vec<f32>,
}

impl ProDmpTablesOwned {
    /// Copies the tables of a baked decoder.
    pub fn from_baked<const N: usize, const P: usize>(baked: &BakedProDmp<N, P>) -> Self {
        Self {
            pos_params: baked.pos_params.as_flattened().to_vec(),
            vel_params: baked.vel_params.as_flattened().to_vec(),
            pos_y0: baked.pos_y0.to_vec(),
            pos_v0: baked.pos_v0.to_vec(),
            vel_y0: baked.vel_y0.to_vec(),
            vel_v0: baked.vel_v0.to_vec(),
        }
    }

    /// The tables as frmd-core's decoder view.
    pub fn view(&self) -> ProDmpTables<'_> {
        ProDmpTables {
            pos_params: &self.pos_params,
            vel_params: &self.vel_params,
            pos_y0: &self.pos_y0,
            pos_v0: &self.pos_v0,
            vel_y0: &self.vel_y0,
            vel_v0: &self.vel_v0,
        }
    }

    /// Tables for `cfg` at the policy's query times `tau/n .. tau` (as
    /// [`frmd_core::prodmp::BakedProDmp::from_config`], for run-time sizes).
    pub fn from_config(cfg: &ProDmpConfig, horizon: usize) -> anyhow::Result<Self> {
        let decoder = ProDmp::new(cfg).context("ProDMP config")?;
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
                .with_context(|| format!("ProDMP row {step}"))?;
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

/// Refuses a checkpoint that is not a student: its sampler needs many network evaluations.
pub(crate) fn check_student(meta: &CheckpointMeta) -> anyhow::Result<()> {
    if meta.role != Role::Student {
        bail!(
            "this is a {} checkpoint; only students can be exported (its sampler needs many network evaluations)",
            meta.role
        );
    }
    Ok(())
}

/// The parts of a student checkpoint that do not depend on its backbone: what every folded
/// network carries besides its layers.
#[derive(Clone, Debug)]
pub struct StudentBase {
    /// The model configuration.
    pub config: ModelConfig,
    /// The noise schedule.
    pub sigma: SigmaConfig,
    /// The step table.
    pub steps: Vec<StepConstants>,
    /// The model input layout ([`input_layout`]).
    pub layout: InputLayout,
    /// The decoder tables at the policy's query times.
    pub prodmp: ProDmpTablesOwned,
    /// Per step, the noise embedding the network folds in ([`step_embeddings`]).
    pub embeddings: Vec<Vec<f32>>,
}

impl StudentBase {
    /// The shared parts of `meta` for `steps` sampling steps; refuses a checkpoint that is not a
    /// student (its sampler needs many network evaluations) or has no ProDMP head.
    pub fn new(meta: &CheckpointMeta, steps: usize) -> anyhow::Result<Self> {
        check_student(meta)?;
        let config = &meta.model;
        let prodmp = config.prodmp().context("a student needs a ProDMP head")?;
        let output = config.prodmp_output().unwrap_or_default();
        let steps = step_constants(&meta.sigma, output, steps)?;
        Ok(Self {
            config: config.clone(),
            sigma: meta.sigma,
            embeddings: step_embeddings(&meta.sigma, steps.len(), config.embed_dim)?,
            steps,
            layout: input_layout(config)?,
            prodmp: ProDmpTablesOwned::from_config(&prodmp, config.horizon)?,
        })
    }

    /// The host consistency sampler ([`sample_chunk`]) with this student's tables.
    pub fn sample(
        &self,
        cond: &[f32],
        noise: &[f32],
        forward: impl FnMut(usize, &[f32]) -> anyhow::Result<Vec<f32>>,
    ) -> anyhow::Result<Vec<f32>> {
        sample_chunk(
            &self.config,
            &self.layout,
            &self.steps,
            &self.prodmp,
            cond,
            noise,
            forward,
        )
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
    (0..steps)
        .map(|i| {
            let level = sigma
                .consistency_sampling_sigma(i, steps)
                .context("sampling level")?;
            let step =
                StepConstants::consistency(sigma, level, i as u32).context("step constants")?;
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

/// The noise embedding `embedding(c_noise(sigma_i))` of every sampling step of a
/// `steps`-step sampler, `embed_dim` values each (computed in f64, rounded to f32).
pub fn step_embeddings(
    sigma: &SigmaConfig,
    steps: usize,
    embed_dim: usize,
) -> anyhow::Result<Vec<Vec<f32>>> {
    let mut embedding = vec![0.0f64; embed_dim];
    (0..steps)
        .map(|i| {
            let level = sigma
                .consistency_sampling_sigma(i, steps)
                .context("sampling level")?;
            let c_noise = sigma.c_noise(level).context("c_noise")?;
            noise_embedding(c_noise, &mut embedding).context("noise embedding")?;
            Ok(embedding.iter().map(|&e| e as f32).collect())
        })
        .collect()
}

/// The float models' input order: `[obs history, y0, v0 * control_dt, c_in x]` (the noise
/// embedding is folded into the network: the MLP's first-layer bias, the transformer's noise
/// token).
pub fn input_layout(config: &ModelConfig) -> anyhow::Result<InputLayout> {
    InputLayout::new(
        &[
            InputSegment::ObsHistory,
            InputSegment::PrevAction,
            InputSegment::PrevRate,
            InputSegment::NoisyTrajectory,
        ],
        config.control_dt as f32,
    )
    .context("input layout")
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
