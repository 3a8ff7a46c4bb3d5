//! The demonstration file format of docs/design.md section 4 and its validating reader.
//!
//! A dataset is a safetensors file with `obs` [T, O] f32, `action` [T, A] f32 and `episode_ends`
//! [E] i64 (cumulative exclusive ends, strictly increasing, the last equal to T), plus string
//! metadata `task`, `dt` (control period, seconds) and `source` (who produced it), optionally
//! `action_before_start` ([`ActionBeforeStart`]), and any further string metadata an importer
//! records (kept as [`Dataset::extra`]).
use anyhow::Context;
use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Demonstrations: per-step observations and commanded actions, concatenated over episodes.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// [T, obs_dim], row-major.
    pub obs: Vec<f32>,
    /// [T, action_dim], row-major.
    pub action: Vec<f32>,
    /// Exclusive end row of each episode, strictly increasing, last = T.
    pub episode_ends: Vec<i64>,
    pub obs_dim: usize,
    pub action_dim: usize,
    pub task: String,
    /// Control period, seconds.
    pub dt: f32,
    pub source: String,
    /// The command in force before each episode's first step (the training windows' a_{-1}).
    pub action_before_start: ActionBeforeStart,
    /// Further metadata, written and read back as is (e.g. `frmd import lerobot`'s source
    /// dataset, fps and episode count). Keys must not be one of the fields above.
    pub extra: BTreeMap<String, String>,
}

/// The metadata keys of the fields of [`Dataset`] (not allowed in [`Dataset::extra`]).
const KNOWN_METADATA: [&str; 4] = ["task", "dt", "source", "action_before_start"];

/// What was commanded before an episode began: what the training windows use as a_{-1} and
/// a_{-2}, and what a deployed policy is reset with. Metadata `action_before_start`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ActionBeforeStart {
    /// The episode's first action, rate 0 (`first`, the default): position commands, where a
    /// robot at rest holds its current position (the built-in tasks).
    #[default]
    First,
    /// The zero action, rate 0 (`zero`): displacement or velocity commands, where rest is zero
    /// (MetaWorld). `frmd serve` resets with zeros unless told otherwise, which matches.
    Zero,
}

impl ActionBeforeStart {
    /// The metadata value.
    pub fn as_str(self) -> &'static str {
        match self {
            ActionBeforeStart::First => "first",
            ActionBeforeStart::Zero => "zero",
        }
    }

    /// Parses the metadata value (`first` or `zero`).
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        match text {
            "first" => Ok(ActionBeforeStart::First),
            "zero" => Ok(ActionBeforeStart::Zero),
            other => anyhow::bail!(
                "metadata `action_before_start` is {other:?}, expected \"first\" or \"zero\""
            ),
        }
    }
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn i64_bytes(values: &[i64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Reads a tensor by name, checking dtype and rank, and returns (shape, data).
fn tensor<'a>(
    file: &SafeTensors<'a>,
    name: &str,
    dtype: Dtype,
    rank: usize,
) -> anyhow::Result<(Vec<usize>, &'a [u8])> {
    let view: TensorView<'a> = file.tensor(name).map_err(|_| {
        anyhow::anyhow!(
            "missing tensor `{name}` (found: {})",
            file.names().join(", ")
        )
    })?;
    anyhow::ensure!(
        view.dtype() == dtype,
        "tensor `{name}` has dtype {:?}, expected {dtype:?}",
        view.dtype()
    );
    anyhow::ensure!(
        view.shape().len() == rank,
        "tensor `{name}` has shape {:?} (rank {}), expected rank {rank}",
        view.shape(),
        view.shape().len()
    );
    Ok((view.shape().to_vec(), view.data()))
}

fn metadata<'m>(meta: &'m Option<HashMap<String, String>>, key: &str) -> anyhow::Result<&'m str> {
    meta.as_ref()
        .and_then(|m| m.get(key))
        .map(String::as_str)
        .ok_or_else(|| anyhow::anyhow!("missing metadata `{key}`"))
}

impl Dataset {
    /// Hand-made demonstrations of the `toy` task for unit tests: `obs` and `action` row-major,
    /// control period 0.1 s.
    #[cfg(test)]
    pub(crate) fn handmade(
        obs: Vec<f32>,
        action: Vec<f32>,
        episode_ends: Vec<i64>,
        (obs_dim, action_dim): (usize, usize),
    ) -> Dataset {
        Dataset {
            obs,
            action,
            episode_ends,
            obs_dim,
            action_dim,
            task: "toy".into(),
            dt: 0.1,
            source: "test".into(),
            action_before_start: Default::default(),
            extra: BTreeMap::new(),
        }
    }

    /// Number of steps T.
    pub fn len(&self) -> usize {
        self.action.len().checked_div(self.action_dim).unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn num_episodes(&self) -> usize {
        self.episode_ends.len()
    }

    /// Row ranges of the episodes (valid after [`Dataset::validate`]).
    pub fn episode_ranges(&self) -> Vec<std::ops::Range<usize>> {
        let mut start = 0usize;
        self.episode_ends
            .iter()
            .map(|&end| {
                let range = start..end as usize;
                start = end as usize;
                range
            })
            .collect()
    }

    /// Checks every invariant of the format and names the first violation.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.obs_dim > 0, "obs_dim is 0");
        anyhow::ensure!(self.action_dim > 0, "action_dim is 0");
        anyhow::ensure!(
            self.obs.len().is_multiple_of(self.obs_dim),
            "obs has {} values, not a multiple of obs_dim {}",
            self.obs.len(),
            self.obs_dim
        );
        anyhow::ensure!(
            self.action.len().is_multiple_of(self.action_dim),
            "action has {} values, not a multiple of action_dim {}",
            self.action.len(),
            self.action_dim
        );
        let steps = self.obs.len() / self.obs_dim;
        anyhow::ensure!(
            steps == self.len(),
            "obs has {steps} rows but action has {} rows",
            self.len()
        );
        anyhow::ensure!(steps > 0, "dataset has no steps");
        anyhow::ensure!(!self.episode_ends.is_empty(), "episode_ends is empty");
        let mut previous = 0i64;
        for (index, &end) in self.episode_ends.iter().enumerate() {
            anyhow::ensure!(
                end > previous,
                "episode_ends is not strictly increasing: entry {index} is {end} after {previous}"
            );
            previous = end;
        }
        anyhow::ensure!(
            previous as usize == steps,
            "last episode end is {previous} but the dataset has {steps} steps"
        );
        for (name, values, dim) in [
            ("obs", &self.obs, self.obs_dim),
            ("action", &self.action, self.action_dim),
        ] {
            if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                anyhow::bail!(
                    "tensor `{name}` has a non-finite value {} at row {}, column {}",
                    values[index],
                    index / dim,
                    index % dim
                );
            }
        }
        anyhow::ensure!(
            self.dt.is_finite() && self.dt > 0.0,
            "dt is {}, expected a positive number of seconds",
            self.dt
        );
        anyhow::ensure!(!self.task.is_empty(), "task name is empty");
        if let Some(key) = self
            .extra
            .keys()
            .find(|k| KNOWN_METADATA.contains(&k.as_str()))
        {
            anyhow::bail!("extra metadata `{key}` would replace the field of the same name");
        }
        Ok(())
    }

    /// Serializes to safetensors bytes (after validation).
    pub fn to_bytes(&self) -> anyhow::Result<Vec<u8>> {
        self.validate()?;
        let steps = self.len();
        let (obs, action, ends) = (
            f32_bytes(&self.obs),
            f32_bytes(&self.action),
            i64_bytes(&self.episode_ends),
        );
        let tensors = [
            (
                "obs",
                TensorView::new(Dtype::F32, vec![steps, self.obs_dim], &obs)?,
            ),
            (
                "action",
                TensorView::new(Dtype::F32, vec![steps, self.action_dim], &action)?,
            ),
            (
                "episode_ends",
                TensorView::new(Dtype::I64, vec![self.episode_ends.len()], &ends)?,
            ),
        ];
        let mut meta = self.extra.clone();
        meta.extend([
            ("task".to_string(), self.task.clone()),
            ("dt".to_string(), self.dt.to_string()),
            ("source".to_string(), self.source.clone()),
        ]);
        // Written only when it is not the default, so files of the built-in tasks stay as they were.
        if self.action_before_start != ActionBeforeStart::default() {
            meta.insert(
                "action_before_start".to_string(),
                self.action_before_start.as_str().to_string(),
            );
        }
        frmd_formats::safetensors_bytes::serialize(tensors, &meta)
    }

    /// Parses and validates safetensors bytes.
    pub fn from_bytes(bytes: &[u8]) -> anyhow::Result<Dataset> {
        let file = SafeTensors::deserialize(bytes)
            .context("not a valid safetensors file (truncated or corrupt header/data)")?;
        let (_, meta) = SafeTensors::read_metadata(bytes)
            .context("not a valid safetensors file (truncated or corrupt header)")?;
        let meta = meta.metadata();
        let (obs_shape, obs) = tensor(&file, "obs", Dtype::F32, 2)?;
        let (action_shape, action) = tensor(&file, "action", Dtype::F32, 2)?;
        let (_, ends) = tensor(&file, "episode_ends", Dtype::I64, 1)?;
        anyhow::ensure!(
            obs_shape[0] == action_shape[0],
            "obs has {} rows but action has {} rows",
            obs_shape[0],
            action_shape[0]
        );
        let dt_text = metadata(meta, "dt")?;
        let dt: f32 = dt_text
            .parse::<f32>()
            .with_context(|| format!("metadata `dt` is {dt_text:?}, not a number"))?;
        let dataset = Dataset {
            obs: obs
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            action: action
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            episode_ends: ends
                .chunks_exact(8)
                .map(|b| i64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                .collect(),
            obs_dim: obs_shape[1],
            action_dim: action_shape[1],
            task: metadata(meta, "task")?.to_string(),
            dt,
            source: metadata(meta, "source")?.to_string(),
            action_before_start: match meta.as_ref().and_then(|m| m.get("action_before_start")) {
                Some(text) => ActionBeforeStart::parse(text)?,
                None => ActionBeforeStart::default(),
            },
            extra: meta
                .iter()
                .flatten()
                .filter(|(k, _)| !KNOWN_METADATA.contains(&k.as_str()))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect(),
        };
        dataset.validate()?;
        Ok(dataset)
    }

    /// Loads and validates a dataset file; errors name the file and what is wrong.
    pub fn load(path: &Path) -> anyhow::Result<Dataset> {
        let bytes = std::fs::read(path)
            .with_context(|| format!("cannot read dataset {}", path.display()))?;
        Self::from_bytes(&bytes).with_context(|| format!("invalid dataset {}", path.display()))
    }

    /// Validates and writes the dataset to `path`.
    pub fn save(&self, path: &Path) -> anyhow::Result<()> {
        let bytes = self.to_bytes()?;
        frmd_formats::artifact::write_atomic(path, &bytes)
    }
}
