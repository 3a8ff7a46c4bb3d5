//! What `frmd serve` serves: a float checkpoint (teacher, student, DP), a baked int8 module or an
//! int8 blob, behind the protocol's [`ServedPolicy`], with the [`ModelInfo`] its HELLO_OK
//! announces.
use super::frame::{FloatType, MAX_NAME, MAX_PAYLOAD};
use super::reply::ModelInfo;
use super::session::{ActInput, ServedPolicy, Session};
use crate::diffusion::samplers::Solver;
use crate::export::{ExportConfig, EXPORT_INFO_FILE};
use crate::firmware::Board;
use crate::policy::float::FloatPolicy;
use crate::policy::int8::Int8Policy;
use crate::tasks::{Policy, PolicyInput};
use anyhow::{bail, Context};
use frmd_export::bake::BLOB_FILE;
use std::path::{Path, PathBuf};

/// Where the served policy comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum PolicySource {
    /// A float checkpoint directory; `steps` and `solver` override the role's default sampler
    /// (teacher Heun 10, student 1 step, DP DDIM 10; DP with 100 steps is DDPM).
    Checkpoint {
        /// The checkpoint directory.
        dir: PathBuf,
        /// Sampling steps.
        steps: Option<usize>,
        /// The teacher's ODE solver.
        solver: Option<Solver>,
    },
    /// A baked module directory (`frmd export --out`): its `policy.blob`.
    Baked(PathBuf),
    /// An int8 blob file (`frmd export --blob`).
    Blob(PathBuf),
    /// The `pil` firmware image on a QEMU core (`crate::firmware`), baking `baked`'s module (or
    /// the checked-in reach student): every chunk comes from the emulated MCU.
    Firmware {
        /// The core.
        board: Board,
        /// A baked module directory to bake into the image.
        baked: Option<PathBuf>,
    },
}

/// Server settings beyond the policy; `Default` is what `frmd serve` uses without options.
#[derive(Clone, Debug, PartialEq)]
pub struct ServeConfig {
    /// Value type of observations and actions on the wire.
    pub float_type: FloatType,
    /// Actions the client should execute per chunk (announced in HELLO_OK); `None`: 8, at most
    /// the horizon.
    pub exec_steps: Option<u16>,
    /// Control period announced in HELLO_OK and used for the previous action's rate; `None`: the
    /// checkpoint's (for a bare blob: the `export.json` beside it, else 0 = unknown, rate 0).
    pub dt: Option<f64>,
    /// The previous action at the start of an episode when RESET carries none; `None`: zeros.
    pub init_action: Option<Vec<f64>>,
    /// Answer every ACT with a zero chunk of the model's shape without running the model (to
    /// measure the protocol's own cost).
    pub zeros: bool,
}

impl Default for ServeConfig {
    fn default() -> Self {
        ServeConfig {
            float_type: FloatType::F32,
            exec_steps: None,
            dt: None,
            init_action: None,
            zeros: false,
        }
    }
}

/// Executed actions per chunk when the configuration does not say (as `frmd eval`).
pub const DEFAULT_EXEC_STEPS: u16 = 8;

/// A loaded policy, ready to serve: its announcement, the default initial action and the model.
pub struct Served {
    pub info: ModelInfo,
    pub default_init: Vec<f64>,
    pub policy: Adapter,
}

impl Served {
    /// A fresh session for one connection.
    pub fn session(&self) -> anyhow::Result<Session> {
        Session::new(self.info.clone(), self.default_init.clone())
            .map_err(anyhow::Error::msg)
            .context("server setup")
    }
}

/// An evaluation [`Policy`] as a [`ServedPolicy`]: f64 wire values to f32 model inputs and back.
pub struct Adapter {
    policy: Box<dyn Policy + Send>,
    history: usize,
    obs_dim: usize,
    chunk_len: usize,
    zeros: bool,
}

impl Adapter {
    pub fn new(
        policy: Box<dyn Policy + Send>,
        history: usize,
        obs_dim: usize,
        chunk_len: usize,
        zeros: bool,
    ) -> Self {
        Adapter {
            policy,
            history,
            obs_dim,
            chunk_len,
            zeros,
        }
    }
}

impl ServedPolicy for Adapter {
    fn reset(&mut self, seed: u64) {
        self.policy.reset(seed);
    }

    fn act(&mut self, input: &ActInput<'_>) -> Result<Vec<f64>, String> {
        if self.zeros {
            return Ok(vec![0.0; self.chunk_len]);
        }
        if input.obs.len() != self.history * self.obs_dim {
            return Err(format!(
                "{} observation values, expected {} x {}",
                input.obs.len(),
                self.history,
                self.obs_dim
            ));
        }
        let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let obs: Vec<Vec<f32>> = input.obs.chunks_exact(self.obs_dim).map(to_f32).collect();
        let (prev, rate) = (to_f32(input.prev_action), to_f32(input.prev_rate));
        let chunk = self
            .policy
            .act(&PolicyInput {
                obs_history: &obs,
                prev_action: &prev,
                prev_rate: &rate,
            })
            .map_err(|e| format!("{e:#}"))?;
        Ok(chunk.iter().flatten().map(|&v| f64::from(v)).collect())
    }
}

fn dim(what: &str, value: usize, source: &str) -> anyhow::Result<u16> {
    u16::try_from(value).with_context(|| {
        format!("{source}: {what} {value} does not fit the protocol's 16-bit field")
    })
}

/// `name` cut to the protocol's limit at a character boundary.
fn short_name(name: String) -> String {
    let mut end = name.len().min(MAX_NAME);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    name[..end].to_string()
}

/// The control period of the checkpoint a baked directory or blob was exported from (via the
/// `export.json` beside the blob), if any. A relative `checkpoint` in `export.json` is tried
/// against the export's own directory first, then against the working directory; when
/// `export.json` exists but its checkpoint cannot be read, the server says so on stderr (unless
/// `--dt` overrides the period) and announces `dt` = 0.
fn exported_dt(dir: &Path, warn: bool) -> anyhow::Result<Option<f64>> {
    let path = dir.join(EXPORT_INFO_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let info = ExportConfig::read(dir)?;
    if info.checkpoint.is_empty() {
        bail!("{}: field `checkpoint` is missing or empty (expected the exported checkpoint directory)", path.display());
    }
    let named = Path::new(&info.checkpoint);
    let candidates = if named.is_absolute() {
        vec![named.to_path_buf()]
    } else {
        vec![dir.join(named), named.to_path_buf()]
    };
    for candidate in &candidates {
        if let Ok(meta) = frmd_formats::checkpoint::CheckpointMeta::read(candidate) {
            return Ok(Some(meta.model.control_dt));
        }
    }
    // The checkpoint may have moved since the export; the blob alone still serves.
    if warn {
        let tried: Vec<String> = candidates.iter().map(|c| c.display().to_string()).collect();
        eprintln!(
            "warning: {}: field `checkpoint` names {}, which has no readable frmd.json (tried {}); \
             HELLO_OK announces dt = 0 (pass --dt SECONDS to set it)",
            path.display(),
            info.checkpoint,
            tried.join(", ")
        );
    }
    Ok(None)
}

/// Loads the policy `source` names with the settings of `cfg`.
pub fn load(source: &PolicySource, cfg: &ServeConfig) -> anyhow::Result<Served> {
    // (policy, history, obs_dim, action_dim, horizon, dt, name)
    let (policy, history, obs_dim, action_dim, horizon, dt, name): (
        Box<dyn Policy + Send>,
        usize,
        usize,
        usize,
        usize,
        f64,
        String,
    ) = match source {
        PolicySource::Checkpoint { dir, steps, solver } => {
            let policy = FloatPolicy::load(dir, *steps, *solver)?;
            let c = policy.config().clone();
            let name = format!("{} {}", policy.name(), dir.display());
            (
                Box::new(policy),
                c.history,
                c.obs_dim,
                c.action_dim,
                c.horizon,
                c.control_dt,
                name,
            )
        }
        PolicySource::Baked(dir) | PolicySource::Blob(dir) => {
            let (path, beside) = match source {
                PolicySource::Baked(_) => (dir.join(BLOB_FILE), dir.clone()),
                _ => (
                    dir.clone(),
                    dir.parent().map(Path::to_path_buf).unwrap_or_default(),
                ),
            };
            let policy = Int8Policy::load(&path)?;
            let (d, name) = (policy.dims(), policy.name());
            let dt = exported_dt(&beside, cfg.dt.is_none())?.unwrap_or(0.0);
            (
                Box::new(policy),
                d.history,
                d.obs_dim,
                d.action_dim,
                d.horizon,
                dt,
                format!("{name} {}", path.display()),
            )
        }
        PolicySource::Firmware { board, baked } => {
            let image =
                crate::firmware::build(&crate::firmware::default_repo(), *board, baked.as_deref())?;
            let policy = crate::firmware::policy::FirmwarePolicy::start(&image)?;
            let i = policy.info().clone();
            let dt = match baked {
                Some(dir) => exported_dt(dir, cfg.dt.is_none())?.unwrap_or(0.0),
                None => 0.0,
            };
            (
                Box::new(policy),
                i.history,
                i.obs_dim,
                i.action_dim,
                i.horizon,
                dt,
                format!("firmware {} ({})", i.board, i.core),
            )
        }
    };
    let what = match source {
        PolicySource::Checkpoint { dir, .. }
        | PolicySource::Baked(dir)
        | PolicySource::Blob(dir) => dir.display().to_string(),
        PolicySource::Firmware { board, .. } => format!("firmware {board}"),
    };
    let horizon16 = dim("horizon", horizon, &what)?;
    let exec_steps = match cfg.exec_steps {
        Some(e) if e == 0 || e > horizon16 => {
            bail!("--exec-steps {e} is outside 1..={horizon} (the policy's horizon)")
        }
        Some(e) => e,
        None => DEFAULT_EXEC_STEPS.min(horizon16),
    };
    let dt = cfg.dt.unwrap_or(dt);
    let default_init = match &cfg.init_action {
        None => vec![0.0; action_dim],
        Some(a) if a.len() != action_dim => bail!(
            "--init-action has {} values, the policy's action_dim is {action_dim}",
            a.len()
        ),
        Some(a) => a.clone(),
    };
    let info = ModelInfo {
        obs_dim: dim("obs_dim", obs_dim, &what)?,
        action_dim: dim("action_dim", action_dim, &what)?,
        obs_history: dim("history", history, &what)?,
        horizon: horizon16,
        exec_steps,
        float_type: cfg.float_type,
        max_payload: MAX_PAYLOAD,
        dt,
        name: short_name(name),
    };
    info.validate()
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("{what}: cannot be served"))?;
    let policy = Adapter::new(policy, history, obs_dim, horizon * action_dim, cfg.zeros);
    Ok(Served {
        info,
        default_init,
        policy,
    })
}
