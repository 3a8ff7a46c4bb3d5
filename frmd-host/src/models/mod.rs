//! Float denoising networks (candle): a backbone conditioned on the observation history, the
//! last action and its rate, and the noise level; either a ProDMP head (teacher and student,
//! k (b+1) parameters decoded to a trajectory in the graph) or a raw n k head (DP baseline).
pub(crate) mod act;
pub mod decoder;
pub(crate) mod init;
pub(crate) mod mlp;
pub(crate) mod transformer;

pub use act::Activation;
pub use frmd_core::prodmp::ProDmpConfig;

use candle_core::{DType, Device, Tensor, D};
use candle_nn::{VarBuilder, VarMap};
use decoder::ProDmpDecoder;

pub use frmd_formats::checkpoint::{BackboneConfig, HeadConfig, ModelConfig, ProDmpOutput};

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
    pub fn from_slices(
        cfg: &ModelConfig,
        obs: &[f32],
        y0: &[f32],
        v0: &[f32],
        device: &Device,
    ) -> anyhow::Result<Self> {
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
            BackboneConfig::Transformer {
                layers,
                heads,
                width,
            } => Backbone::Transformer(transformer::Transformer::new(
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
        Ok(Network {
            cfg: cfg.clone(),
            backbone,
            decoder,
        })
    }

    pub fn config(&self) -> &ModelConfig {
        &self.cfg
    }

    /// Name prefix of the output layer's variables (the layer that emits ProDMP parameters or
    /// the raw trajectory).
    pub fn output_layer_prefix(&self) -> String {
        match &self.cfg.backbone {
            BackboneConfig::Mlp { hidden, .. } => format!("mlp.layers.{}.", hidden.len()),
            BackboneConfig::Transformer { .. } => "transformer.head.".to_string(),
        }
    }

    /// The backbone's raw output [B, output_dim] (ProDMP parameters or a raw trajectory).
    pub fn raw_output(
        &self,
        x_scaled: &Tensor,
        cond: &Condition,
        emb: &Tensor,
    ) -> anyhow::Result<Tensor> {
        Ok(match &self.backbone {
            Backbone::Mlp(m) => m.forward(x_scaled, &cond.features, emb)?,
            Backbone::Transformer(t) => t.forward(x_scaled, &cond.features, emb)?,
        })
    }

    /// The ProDMP decoder's initial-condition part `decode(0, y0, v0)` [B, n k] of this
    /// condition (an error for a raw head).
    pub fn boundary(&self, cond: &Condition) -> anyhow::Result<Tensor> {
        match &self.decoder {
            Some(dec) => dec.boundary(&cond.y0, &cond.v0),
            None => anyhow::bail!("a raw-head network has no ProDMP boundary terms"),
        }
    }

    /// Trajectory-shaped output [B, n k]: the decoded ProDMP trajectory, or the raw output.
    pub fn predict(
        &self,
        x_scaled: &Tensor,
        cond: &Condition,
        emb: &Tensor,
    ) -> anyhow::Result<Tensor> {
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
    /// Builds the network and initializes every variable from `seed` (see `init::init_seeded`).
    pub fn new_seeded(cfg: &ModelConfig, seed: u64, device: &Device) -> anyhow::Result<Self> {
        let varmap = VarMap::new();
        let net = Network::new(cfg, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
        init::init_seeded(&varmap, seed)?;
        Ok(OwnedNetwork { varmap, net })
    }

    /// A network with the same config and a copy of these variable values.
    pub fn duplicate(&self, device: &Device) -> anyhow::Result<Self> {
        self.duplicate_as(self.net.config(), device)
    }

    /// A copy of these variable values in a network of config `cfg`, which must have the same
    /// variables (e.g. another output parametrization).
    pub fn duplicate_as(&self, cfg: &ModelConfig, device: &Device) -> anyhow::Result<Self> {
        let copy = OwnedNetwork::new_seeded(cfg, 0, device)?;
        init::copy_values(&self.varmap, &copy.varmap)?;
        Ok(copy)
    }
}
