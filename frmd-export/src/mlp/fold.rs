//! The MLP student folded into the runtime's structure, in f32: the shared parts
//! ([`StudentBase`]: step table, input layout, decoder tables) and the noise embedding of each
//! step folded into a first-layer bias variant. The result ([`FoldedMlp`]) runs on frmd-core's own
//! f32 path ([`frmd_core::model::mlp::F32Mlp`]) and is what calibration and quantization start
//! from.
//!
//! Input gains: the model input is quantized with one int8 scale for the whole vector, and the
//! `c_in`-scaled noisy trajectory (about +-4.5 at sigma_max) would otherwise set that scale for
//! the observations (+-1). [`FoldedMlp::with_input_gains`] multiplies the trajectory segment by
//! `traj_gain` (folded into every step's baked `c_in`) and the rate segment by `rate_gain` (folded
//! into the layout's `rate_scale`), and divides the matching first-layer weight columns by the
//! same gains, so the f32 function is unchanged while every segment spans about the same range.
//! The baked `c_in` is therefore `c_in(sigma) * traj_gain`.
use crate::fold::{FloatLayer, StudentBase};
use crate::host::MAX_WIDTH;
use anyhow::{bail, Context};
use frmd_core::kernels::Activation as KernelActivation;
use frmd_core::model::linear::F32Linear;
use frmd_core::model::mlp::{F32Mlp, F32Scratch, Probe};
use frmd_core::policy::{F32MlpNetwork, MAX_HIDDEN_LAYERS};
use frmd_formats::checkpoint::{Activation, BackboneConfig, Checkpoint};

/// A student MLP folded for `steps` sampling steps.
#[derive(Clone, Debug)]
pub struct FoldedMlp {
    /// What every student carries (its step constants and layout carry the input gains).
    pub base: StudentBase,
    /// Hidden layers; the first one's weights lack the embedding columns.
    pub hidden: Vec<FloatLayer>,
    /// Output layer.
    pub output: FloatLayer,
    /// Per step: first hidden layer bias with `W_emb . embedding(c_noise(sigma_i))` added.
    pub first_layer_biases: Vec<Vec<f32>>,
    /// Input gains applied so far (1 after [`FoldedMlp::new`]).
    pub gains: InputGains,
}

/// Factors on the trajectory and rate input segments (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputGains {
    /// Factor on the noisy trajectory segment (folded into `c_in`).
    pub traj_gain: f32,
    /// Factor on the previous-rate segment (folded into the layout's `rate_scale`).
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

impl FoldedMlp {
    /// Folds a student MLP checkpoint for `steps` sampling steps, refusing what the runtime
    /// cannot represent.
    pub fn new(ckpt: &Checkpoint, steps: usize) -> anyhow::Result<Self> {
        let base = StudentBase::new(&ckpt.meta, steps)?;
        let config = &base.config;
        let (hidden_sizes, activation) = match &config.backbone {
            BackboneConfig::Mlp { hidden, activation } => (hidden.clone(), *activation),
            BackboneConfig::Transformer { .. } => {
                bail!("a transformer backbone folds with transformer::FoldedTransformer")
            }
        };
        if hidden_sizes.len() > MAX_HIDDEN_LAYERS {
            bail!(
                "{} hidden layers exceed the runtime limit of {MAX_HIDDEN_LAYERS}",
                hidden_sizes.len()
            );
        }
        let input_width = base
            .layout
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
        let first_layer_biases: Vec<Vec<f32>> = base
            .embeddings
            .iter()
            .map(|embedding| {
                (0..first.out_features)
                    .map(|o| {
                        let row = &first.weights[o * full_in + input_width..(o + 1) * full_in];
                        let folded: f64 = row
                            .iter()
                            .zip(embedding)
                            .map(|(w, e)| f64::from(*w) * f64::from(*e))
                            .sum();
                        (f64::from(first.bias[o]) + folded) as f32
                    })
                    .collect()
            })
            .collect();
        first.weights = first
            .weights
            .chunks_exact(full_in)
            .flat_map(|row| row[..input_width].iter().copied())
            .collect();
        first.in_features = input_width;
        first.bias = first_layer_biases[0].clone();
        Ok(FoldedMlp {
            base,
            hidden,
            output,
            first_layer_biases,
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
        let c = &self.base.config;
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
        for step in &mut out.base.steps {
            step.c_in *= traj;
        }
        out.base.layout.rate_scale *= rate;
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
            .context("f32 network")
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
            .context("f32 forward")?;
        Ok(out)
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
        self.base.sample(cond, noise, |i, input| {
            self.forward_observed(i, input, |p, v| observe(i, p, v))
        })
    }
}
