//! Float denoising networks (candle): a backbone conditioned on the observation history, the
//! last action and its rate, and the noise level; either a ProDMP head (teacher and student,
//! k (b+1) parameters decoded to a trajectory in the graph) or a raw n k head (DP baseline).
pub mod act;
pub mod decoder;
pub mod init;
pub mod mlp;
pub mod transformer;

pub use act::Activation;
pub use frmd_core::prodmp::ProDmpConfig;

use anyhow::{bail, Context};
use candle_core::{DType, Device, Tensor, D};
use candle_nn::{VarBuilder, VarMap};
use decoder::ProDmpDecoder;
use serde::{Deserialize, Serialize};

/// Backbone architecture and sizes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum BackboneConfig {
    Mlp { hidden: Vec<usize>, activation: Activation },
    Transformer { layers: usize, heads: usize, width: usize },
}

impl BackboneConfig {
    /// Parses `mlp` ([256, 256, 256], Mish), `mlp-paper` ([512, 512, 256, 256]),
    /// `mlp:W1,W2,..[:silu|:mish]`, `transformer-lite` (3 layers, 2 heads, 128) and
    /// `transformer` (6 layers, 4 heads, 256).
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let mlp = |hidden: Vec<usize>, activation| BackboneConfig::Mlp { hidden, activation };
        Ok(match text {
            "mlp" => mlp(vec![256, 256, 256], Activation::Mish),
            "mlp-silu" => mlp(vec![256, 256, 256], Activation::Silu),
            "mlp-paper" => mlp(vec![512, 512, 256, 256], Activation::Mish),
            "transformer-lite" => BackboneConfig::Transformer { layers: 3, heads: 2, width: 128 },
            "transformer" => BackboneConfig::Transformer { layers: 6, heads: 4, width: 256 },
            other => {
                let Some(rest) = other.strip_prefix("mlp:") else {
                    bail!("unknown backbone `{other}` (mlp, mlp-silu, mlp-paper, mlp:W1,W2[:silu|:mish], transformer-lite, transformer)");
                };
                let (widths, activation) = match rest.split_once(':') {
                    Some((w, "silu")) => (w, Activation::Silu),
                    Some((w, "mish")) => (w, Activation::Mish),
                    Some((_, act)) => bail!("unknown activation `{act}` (silu or mish)"),
                    None => (rest, Activation::Mish),
                };
                let hidden = widths
                    .split(',')
                    .map(|w| w.trim().parse::<usize>().ok().filter(|&w| w > 0))
                    .collect::<Option<Vec<_>>>()
                    .with_context(|| format!("bad MLP widths `{widths}` (positive integers, comma separated)"))?;
                mlp(hidden, activation)
            }
        })
    }
}

/// What the network outputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum HeadConfig {
    /// k (b+1) ProDMP parameters, decoded to positions in the graph.
    ProDmp { num_basis: usize },
    /// A raw n k output (the DP baseline's noise prediction).
    Raw,
}

/// Everything that fixes the network's variables and its input/output layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    pub obs_dim: usize,
    /// Observation history m.
    pub history: usize,
    pub action_dim: usize,
    /// Prediction horizon n.
    pub horizon: usize,
    /// Control period, seconds (ProDMP tau = horizon * control_dt).
    pub control_dt: f64,
    /// Length of the noise embedding (`frmd_core::sigma::noise_embedding`).
    pub embed_dim: usize,
    pub backbone: BackboneConfig,
    pub head: HeadConfig,
}

impl ModelConfig {
    /// Width of the condition vector [obs history, y0, v0 * control_dt].
    pub fn cond_dim(&self) -> usize {
        self.history * self.obs_dim + 2 * self.action_dim
    }

    /// n k: length of a trajectory.
    pub fn traj_dim(&self) -> usize {
        self.horizon * self.action_dim
    }

    pub fn prodmp(&self) -> Option<ProDmpConfig> {
        match self.head {
            HeadConfig::ProDmp { num_basis } => {
                Some(ProDmpConfig::policy(self.action_dim, num_basis, self.horizon, self.control_dt))
            }
            HeadConfig::Raw => None,
        }
    }

    pub fn output_dim(&self) -> usize {
        match self.head {
            HeadConfig::ProDmp { num_basis } => self.action_dim * (num_basis + 1),
            HeadConfig::Raw => self.traj_dim(),
        }
    }

    pub fn validate(&self) -> anyhow::Result<()> {
        if self.obs_dim == 0 || self.history == 0 || self.action_dim == 0 || self.horizon == 0 {
            bail!("model config: obs_dim, history, action_dim and horizon must be positive");
        }
        if !(self.control_dt.is_finite() && self.control_dt > 0.0) {
            bail!("model config: control_dt must be finite and positive, got {}", self.control_dt);
        }
        if self.embed_dim == 0 || !self.embed_dim.is_multiple_of(2) {
            bail!("model config: embed_dim must be even and positive, got {}", self.embed_dim);
        }
        match &self.backbone {
            BackboneConfig::Mlp { hidden, .. } if hidden.is_empty() || hidden.contains(&0) => {
                bail!("model config: MLP needs at least one positive hidden width")
            }
            BackboneConfig::Transformer { layers, heads, width }
                if *layers == 0 || *heads == 0 || *width == 0 || width % heads != 0 =>
            {
                bail!("model config: transformer needs layers, heads > 0 and width divisible by heads")
            }
            _ => {}
        }
        if let HeadConfig::ProDmp { num_basis } = self.head {
            if num_basis == 0 {
                bail!("model config: ProDMP needs at least one basis function");
            }
        }
        Ok(())
    }
}

/// Conditioning of one batch, in normalized units.
#[derive(Clone, Debug)]
pub struct Condition {
    /// y0 [B, k]: last commanded action.
    pub y0: Tensor,
    /// v0 [B, k]: its rate, normalized units per second.
    pub v0: Tensor,
    /// [B, cond_dim] = [obs history, y0, v0 * control_dt].
    pub features: Tensor,
}

impl Condition {
    /// `obs` [B, m O], `y0` [B, k], `v0` [B, k].
    pub fn new(obs: &Tensor, y0: Tensor, v0: Tensor, control_dt: f64) -> candle_core::Result<Self> {
        let features = Tensor::cat(&[obs, &y0, &(&v0 * control_dt)?], D::Minus1)?;
        Ok(Condition { y0, v0, features })
    }

    /// Builds a condition from row-major f32 slices.
    pub fn from_slices(cfg: &ModelConfig, obs: &[f32], y0: &[f32], v0: &[f32], device: &Device) -> anyhow::Result<Self> {
        let k = cfg.action_dim;
        let batch = y0.len() / k;
        let obs = Tensor::from_slice(obs, (batch, cfg.history * cfg.obs_dim), device)?;
        let y0 = Tensor::from_slice(y0, (batch, k), device)?;
        let v0 = Tensor::from_slice(v0, (batch, k), device)?;
        Ok(Condition::new(&obs, y0, v0, cfg.control_dt)?)
    }
}

enum Backbone {
    Mlp(mlp::Mlp),
    Transformer(transformer::Transformer),
}

/// Backbone plus head: maps (c_in-scaled noisy trajectory, condition, noise embedding) to a
/// trajectory-shaped output [B, n k].
pub struct Network {
    cfg: ModelConfig,
    backbone: Backbone,
    decoder: Option<ProDmpDecoder>,
}

impl Network {
    pub fn new(cfg: &ModelConfig, vb: VarBuilder) -> anyhow::Result<Self> {
        cfg.validate()?;
        let (input, output) = (cfg.traj_dim(), cfg.output_dim());
        let backbone = match &cfg.backbone {
            BackboneConfig::Mlp { hidden, activation } => Backbone::Mlp(mlp::Mlp::new(
                cfg.cond_dim() + input + cfg.embed_dim,
                hidden,
                output,
                *activation,
                vb.pp("mlp"),
            )?),
            BackboneConfig::Transformer { layers, heads, width } => Backbone::Transformer(transformer::Transformer::new(
                &transformer::TransformerSizes {
                    layers: *layers,
                    heads: *heads,
                    width: *width,
                    horizon: cfg.horizon,
                    action_dim: cfg.action_dim,
                    cond_dim: cfg.cond_dim(),
                    embed_dim: cfg.embed_dim,
                    output,
                },
                vb.pp("transformer"),
            )?),
        };
        let decoder = match cfg.prodmp() {
            Some(pcfg) => Some(ProDmpDecoder::new(&pcfg, cfg.horizon, vb.device())?),
            None => None,
        };
        Ok(Network { cfg: cfg.clone(), backbone, decoder })
    }

    pub fn config(&self) -> &ModelConfig {
        &self.cfg
    }

    /// The backbone's raw output [B, output_dim] (ProDMP parameters or a raw trajectory).
    pub fn raw_output(&self, x_scaled: &Tensor, cond: &Condition, emb: &Tensor) -> anyhow::Result<Tensor> {
        Ok(match &self.backbone {
            Backbone::Mlp(m) => m.forward(x_scaled, &cond.features, emb)?,
            Backbone::Transformer(t) => t.forward(x_scaled, &cond.features, emb)?,
        })
    }

    /// Trajectory-shaped output [B, n k]: the decoded ProDMP trajectory, or the raw output.
    pub fn predict(&self, x_scaled: &Tensor, cond: &Condition, emb: &Tensor) -> anyhow::Result<Tensor> {
        let raw = self.raw_output(x_scaled, cond, emb)?;
        match &self.decoder {
            Some(dec) => dec.decode(&raw, &cond.y0, &cond.v0),
            None => Ok(raw),
        }
    }
}

/// A network with its own variables.
pub struct OwnedNetwork {
    pub varmap: VarMap,
    pub net: Network,
}

impl OwnedNetwork {
    /// Builds the network and initializes every variable from `seed` (see [`init::init_seeded`]).
    pub fn new_seeded(cfg: &ModelConfig, seed: u64, device: &Device) -> anyhow::Result<Self> {
        let varmap = VarMap::new();
        let net = Network::new(cfg, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
        init::init_seeded(&varmap, seed)?;
        Ok(OwnedNetwork { varmap, net })
    }

    /// A network with the same config and a copy of these variable values.
    pub fn duplicate(&self, device: &Device) -> anyhow::Result<Self> {
        let copy = OwnedNetwork::new_seeded(self.net.config(), 0, device)?;
        init::copy_values(&self.varmap, &copy.varmap)?;
        Ok(copy)
    }
}
