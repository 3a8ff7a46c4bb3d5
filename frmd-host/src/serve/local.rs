//! The served policy in process: the loader, session rules and chunk of `frmd serve` without the
//! wire, for bindings (the Python package `frmd-host/python`) and programs that link frmd-host.
//! Same policy, same seed, same `executed` sequence: the same chunks as the server, bit for bit.
use super::error::ProtocolError;
use super::frame::FloatType;
use super::load::{load, PolicySource, ServeConfig, Served};
use super::reply::{Chunk, ModelInfo};
use super::session::Session;
use crate::diffusion::samplers::Solver;
use frmd_export::bake::BLOB_FILE;
use frmd_formats::checkpoint::CONFIG_FILE;
use std::path::Path;

impl PolicySource {
    /// What `path` holds: a checkpoint directory (with `frmd.json`; `steps` and `solver` apply),
    /// a baked export directory (with `policy.blob`) or a blob file.
    pub fn detect(
        path: &Path,
        steps: Option<usize>,
        solver: Option<Solver>,
    ) -> anyhow::Result<Self> {
        if path.is_file() {
            return Ok(PolicySource::Blob(path.to_path_buf()));
        }
        if !path.is_dir() {
            anyhow::bail!("{}: no such file or directory", path.display());
        }
        if path.join(CONFIG_FILE).is_file() {
            Ok(PolicySource::Checkpoint {
                dir: path.to_path_buf(),
                steps,
                solver,
            })
        } else if path.join(BLOB_FILE).is_file() {
            Ok(PolicySource::Baked(path.to_path_buf()))
        } else {
            anyhow::bail!(
                "{}: expected a checkpoint directory (with {CONFIG_FILE}), a baked export (with \
                 {BLOB_FILE}) or a blob file",
                path.display()
            )
        }
    }
}

/// A policy as `frmd serve` serves it, called in process.
pub struct LocalPolicy {
    served: Served,
    session: Session,
}

impl LocalPolicy {
    /// Loads `source` with the server settings `cfg` (as `frmd serve` would).
    pub fn load(source: &PolicySource, cfg: &ServeConfig) -> anyhow::Result<Self> {
        let served = load(source, cfg)?;
        let mut session = served.session()?;
        session.hello();
        Ok(LocalPolicy { served, session })
    }

    /// What HELLO_OK would announce: shapes, horizon, executed steps, `dt`, name.
    pub fn info(&self) -> &ModelInfo {
        &self.served.info
    }

    /// Starts an episode (RESET): noise seeded by `seed`, `init_action` as the previous action
    /// (empty: the default).
    pub fn reset(&mut self, seed: u64, init_action: Vec<f64>) -> Result<(), ProtocolError> {
        let init_action = self.on_wire(init_action);
        self.session
            .reset(seed, init_action, &mut self.served.policy)
    }

    /// Whether this episode has had a chunk.
    pub fn has_chunk(&self) -> bool {
        self.session.has_chunk()
    }

    /// The next chunk (ACT) after `executed` actions of the last one were commanded.
    pub fn act(&mut self, executed: u32, obs: Vec<f64>) -> Result<Chunk, ProtocolError> {
        let obs = self.on_wire(obs);
        self.session.act(executed, obs, &mut self.served.policy)
    }

    /// `values` as the wire would carry them: rounded to f32 when the announced float type is
    /// f32, so a value beyond f32's range becomes infinite and is refused as NON_FINITE, as the
    /// server refuses it.
    fn on_wire(&self, mut values: Vec<f64>) -> Vec<f64> {
        if self.served.info.float_type == FloatType::F32 {
            for v in &mut values {
                *v = f64::from(*v as f32);
            }
        }
        values
    }
}
