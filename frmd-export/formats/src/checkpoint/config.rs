//! The pure-data model configuration stored in `frmd.json` (backbone, head, sizes), shared by
//! the candle models (frmd-host) and the exporter.
use anyhow::{bail, Context};
use frmd_core::prodmp::ProDmpConfig;
use serde::{Deserialize, Serialize};

/// Hidden-layer activation of the MLP backbone.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Activation {
    /// x * sigmoid(x).
    Silu,
    /// x * tanh(softplus(x)).
    Mish,
}

/// Backbone architecture and sizes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum BackboneConfig {
    /// A multilayer perceptron over the concatenated input.
    Mlp {
        /// Hidden layer widths.
        hidden: Vec<usize>,
        /// Hidden-layer activation.
        activation: Activation,
    },
    /// A pre-LayerNorm transformer over condition, noise and trajectory tokens.
    Transformer {
        /// Blocks.
        layers: usize,
        /// Attention heads.
        heads: usize,
        /// Token width.
        width: usize,
    },
}

impl BackboneConfig {
    /// The named backbones: `mlp` ([256, 256, 256], Mish), `mlp-silu`, `mlp-paper`
    /// ([512, 512, 256, 256], Mish), `transformer-lite` (3 layers, 2 heads, 128 wide) and
    /// `transformer` (6 layers, 4 heads, 256 wide).
    pub fn presets() -> [(&'static str, BackboneConfig); 5] {
        let mlp = |hidden: Vec<usize>, activation| BackboneConfig::Mlp { hidden, activation };
        [
            ("mlp", mlp(vec![256, 256, 256], Activation::Mish)),
            ("mlp-silu", mlp(vec![256, 256, 256], Activation::Silu)),
            ("mlp-paper", mlp(vec![512, 512, 256, 256], Activation::Mish)),
            (
                "transformer-lite",
                BackboneConfig::Transformer {
                    layers: 3,
                    heads: 2,
                    width: 128,
                },
            ),
            (
                "transformer",
                BackboneConfig::Transformer {
                    layers: 6,
                    heads: 4,
                    width: 256,
                },
            ),
        ]
    }

    /// The preset called `name`, if there is one.
    pub fn preset(name: &str) -> Option<Self> {
        Self::presets()
            .into_iter()
            .find(|(preset, _)| *preset == name)
            .map(|(_, config)| config)
    }

    /// Parses a preset name ([`Self::presets`]), `mlp:W1,W2,..[:silu|:mish]` (Mish when not
    /// given) or `transformer:LAYERS,HEADS,WIDTH`.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        if let Some(preset) = Self::preset(text) {
            return Ok(preset);
        }
        let numbers = |list: &str| {
            list.split(',')
                .map(|w| w.trim().parse::<usize>().ok().filter(|&w| w > 0))
                .collect::<Option<Vec<_>>>()
                .with_context(|| format!("bad sizes `{list}` (positive integers, comma separated)"))
        };
        if let Some(rest) = text.strip_prefix("transformer:") {
            let &[layers, heads, width] = numbers(rest)?.as_slice() else {
                bail!("`transformer:` takes LAYERS,HEADS,WIDTH, got `{rest}`");
            };
            return Ok(BackboneConfig::Transformer {
                layers,
                heads,
                width,
            });
        }
        let Some(rest) = text.strip_prefix("mlp:") else {
            bail!("unknown backbone `{text}` (mlp, mlp-silu, mlp-paper, mlp:W1,W2[:silu|:mish], transformer-lite, transformer, transformer:L,H,W)");
        };
        let (widths, activation) = match rest.split_once(':') {
            Some((w, "silu")) => (w, Activation::Silu),
            Some((w, "mish")) => (w, Activation::Mish),
            Some((_, act)) => bail!("unknown activation `{act}` (silu or mish)"),
            None => (rest, Activation::Mish),
        };
        Ok(BackboneConfig::Mlp {
            hidden: numbers(widths).context("MLP widths")?,
            activation,
        })
    }
}

impl std::str::FromStr for BackboneConfig {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> anyhow::Result<Self> {
        Self::parse(text)
    }
}

/// The preset name where there is one, else the `mlp:..`/`transformer:..` form (what
/// [`BackboneConfig::parse`] reads back).
impl std::fmt::Display for BackboneConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some((name, _)) = Self::presets()
            .into_iter()
            .find(|(_, preset)| preset == self)
        {
            return f.write_str(name);
        }
        let list = |sizes: &[usize]| {
            sizes
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(",")
        };
        match self {
            BackboneConfig::Mlp {
                hidden,
                activation: Activation::Silu,
            } => write!(f, "mlp:{}:silu", list(hidden)),
            BackboneConfig::Mlp {
                hidden,
                activation: Activation::Mish,
            } => write!(f, "mlp:{}:mish", list(hidden)),
            BackboneConfig::Transformer {
                layers,
                heads,
                width,
            } => write!(f, "transformer:{}", list(&[*layers, *heads, *width])),
        }
    }
}

/// How a ProDMP model turns its decoded trajectory `g = G(E(..); y0, v0)` into its output
/// (docs/design.md, "Parametrization"). With `b = G(0; y0, v0)` the part of every chunk fixed by
/// the initial condition:
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProDmpOutput {
    /// `g`: the decoded trajectory is the output (MPD's choice; every checkpoint written before
    /// the skip existed).
    #[default]
    Direct,
    /// `b + c_skip(sigma) (x - b) + c_out(sigma) (g - b)`: a skip on the free part of the chunk
    /// only, so `y0`, `v0` stay exact. The teacher uses EDM's `c_skip`/`c_out`, the student the
    /// consistency ones (identity at `sigma_min`), both from `frmd_core::sigma`.
    BoundarySkip,
}

impl ProDmpOutput {
    /// Parses `direct` or `boundary-skip`.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        match text {
            "direct" => Ok(ProDmpOutput::Direct),
            "boundary-skip" => Ok(ProDmpOutput::BoundarySkip),
            other => {
                bail!("unknown ProDMP output parametrization `{other}` (direct, boundary-skip)")
            }
        }
    }
}

impl std::str::FromStr for ProDmpOutput {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> anyhow::Result<Self> {
        Self::parse(text)
    }
}

/// The name [`ProDmpOutput::parse`] reads.
impl std::fmt::Display for ProDmpOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ProDmpOutput::Direct => "direct",
            ProDmpOutput::BoundarySkip => "boundary-skip",
        })
    }
}

/// What the network outputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum HeadConfig {
    /// k (b+1) ProDMP parameters, decoded to positions in the graph.
    ProDmp {
        /// Basis functions per DoF (a DoF has `num_basis + 1` parameters with its goal).
        num_basis: usize,
        /// Output parametrization (absent in older checkpoints: `direct`).
        #[serde(default)]
        output: ProDmpOutput,
        /// mp_pytorch's `auto_scale_basis`: every basis column of the decoder is divided by its
        /// largest value, so a unit weight moves the trajectory by about one unit. Without it
        /// the 20 basis columns reach at most ~1e-3 at the policy's 12 query times against ~1
        /// for the goal (singular values 3.1 then 2.6e-3 .. 9.9e-5), and the network has to
        /// output weights of ~1000 to shape a chunk (docs/design.md, "ProDMP scaling").
        /// Absent in older checkpoints: false.
        #[serde(default)]
        auto_scale_basis: bool,
    },
    /// A raw n k output (the DP baseline's noise prediction).
    Raw,
}

impl HeadConfig {
    /// A ProDMP head of `num_basis` basis functions per DoF with direct output and the basis
    /// unscaled (what a checkpoint without the two newer fields reads as).
    pub fn prodmp(num_basis: usize) -> Self {
        HeadConfig::ProDmp {
            num_basis,
            output: ProDmpOutput::Direct,
            auto_scale_basis: false,
        }
    }
}

/// Everything that fixes the network's variables and its input/output layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    /// Observation dimension O.
    pub obs_dim: usize,
    /// Observation history m.
    pub history: usize,
    /// Action dimension (DoF) K.
    pub action_dim: usize,
    /// Prediction horizon n.
    pub horizon: usize,
    /// Control period, seconds (ProDMP tau = horizon * control_dt).
    pub control_dt: f64,
    /// Length of the noise embedding (`frmd_core::sigma::noise_embedding`).
    pub embed_dim: usize,
    /// The network between input and head.
    pub backbone: BackboneConfig,
    /// What the network outputs.
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

    /// The decoder of a ProDMP head (the policy convention for these sizes); `None` for a raw
    /// head.
    pub fn prodmp(&self) -> Option<ProDmpConfig> {
        match self.head {
            HeadConfig::ProDmp {
                num_basis,
                auto_scale_basis,
                ..
            } => {
                let mut cfg =
                    ProDmpConfig::policy(self.action_dim, num_basis, self.horizon, self.control_dt);
                cfg.auto_scale_basis = auto_scale_basis;
                Some(cfg)
            }
            HeadConfig::Raw => None,
        }
    }

    /// The ProDMP output parametrization (`None` for a raw head).
    pub fn prodmp_output(&self) -> Option<ProDmpOutput> {
        match self.head {
            HeadConfig::ProDmp { output, .. } => Some(output),
            HeadConfig::Raw => None,
        }
    }

    /// Width of the network output (`k (b + 1)` ProDMP parameters, or `n k` raw values).
    pub fn output_dim(&self) -> usize {
        match self.head {
            HeadConfig::ProDmp { num_basis, .. } => self.action_dim * (num_basis + 1),
            HeadConfig::Raw => self.traj_dim(),
        }
    }

    /// Every field in its range, named when it is not (the sizes bounded so that a hostile
    /// config cannot ask for unbounded memory).
    pub fn validate(&self) -> anyhow::Result<()> {
        let sizes = [
            ("obs_dim", self.obs_dim, 4096),
            ("history", self.history, 64),
            ("action_dim", self.action_dim, 256),
            ("horizon", self.horizon, 1024),
            ("embed_dim", self.embed_dim, 4096),
        ];
        for (field, value, max) in sizes {
            if !(1..=max).contains(&value) {
                bail!("model.{field} is {value}, expected 1 to {max}");
            }
        }
        if !(self.control_dt.is_finite() && self.control_dt > 0.0) {
            bail!(
                "model.control_dt is {}, expected a finite number of seconds > 0",
                self.control_dt
            );
        }
        if !self.embed_dim.is_multiple_of(2) {
            bail!(
                "model.embed_dim is {}, expected an even number",
                self.embed_dim
            );
        }
        match &self.backbone {
            BackboneConfig::Mlp { hidden, .. } => {
                if hidden.is_empty() || hidden.len() > 64 {
                    bail!(
                        "model.backbone.hidden has {} layers, expected 1 to 64",
                        hidden.len()
                    );
                }
                if let Some((i, w)) = hidden
                    .iter()
                    .enumerate()
                    .find(|(_, w)| !(1..=65_536).contains(*w))
                {
                    bail!("model.backbone.hidden[{i}] is {w}, expected 1 to 65536");
                }
            }
            BackboneConfig::Transformer {
                layers,
                heads,
                width,
            } => {
                for (field, value, max) in [
                    ("layers", *layers, 64),
                    ("heads", *heads, 64),
                    ("width", *width, 65_536),
                ] {
                    if !(1..=max).contains(&value) {
                        bail!("model.backbone.{field} is {value}, expected 1 to {max}");
                    }
                }
                if width % heads != 0 {
                    bail!(
                        "model.backbone.width is {width}, expected a multiple of model.backbone.heads {heads}"
                    );
                }
            }
        }
        if let HeadConfig::ProDmp { num_basis, .. } = self.head {
            if !(1..=256).contains(&num_basis) {
                bail!("model.head.num_basis is {num_basis}, expected 1 to 256");
            }
        }
        Ok(())
    }
}
