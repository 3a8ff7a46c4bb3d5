//! `frmd import lerobot`: a LeRobot dataset (LeRobotDataset v2.0/v2.1 or v3.0, read from its
//! parquet files and `meta/`) as an FRMD demonstration [`Dataset`].
//!
//! The state column becomes `obs`, the action column `action`, each `episode_index` an episode
//! (frames ordered by `frame_index`), `dt` = 1 / `fps`. Image and video features are not read.
//! Everything is checked first, and the first problem is a named [`ImportError`]: a missing file,
//! metadata field or column, a ragged episode (frames not `0..n`, vectors of another length than
//! `info.json` gives, a length other than the episodes metadata's), a non-finite value, or
//! timestamps whose steps disagree with `fps`.
mod error;
mod meta;
mod table;

pub use error::ImportError;
pub use meta::Layout;

use super::{ActionBeforeStart, Dataset};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What to import and how; `Default` is what `frmd import lerobot` uses without options.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportConfig {
    /// The column that becomes the observation.
    pub state_key: String,
    /// The column that becomes the action.
    pub action_key: String,
    /// FRMD's task name; `None`: the dataset directory's name.
    pub task: Option<String>,
    /// What was commanded before each episode (LeRobot's actions are mostly joint or pose
    /// targets, so the default is `first`).
    pub action_before_start: ActionBeforeStart,
    /// Largest allowed difference between a timestamp step and 1 / fps, seconds.
    pub fps_tolerance: f64,
}

impl Default for ImportConfig {
    fn default() -> Self {
        ImportConfig {
            state_key: "observation.state".into(),
            action_key: "action".into(),
            task: None,
            action_before_start: ActionBeforeStart::First,
            fps_tolerance: 1e-3,
        }
    }
}

/// The imported dataset and what the import found.
#[derive(Clone, Debug)]
pub struct Imported {
    pub dataset: Dataset,
    /// `codebase_version` of `info.json`.
    pub version: String,
    pub layout: Layout,
    pub fps: f64,
    /// Data files read.
    pub files: usize,
    /// Features not imported (images, videos, other columns), with their dtype.
    pub ignored: Vec<String>,
    /// Whether the episodes metadata was there to check the episode lengths against.
    pub episodes_checked: bool,
}

/// One frame of an episode as read.
struct Frame {
    index: i64,
    timestamp: f64,
    state: Vec<f64>,
    action: Vec<f64>,
    file: usize,
}

/// Reads and checks the LeRobot dataset in `dir`.
pub fn import(dir: &Path, cfg: &ImportConfig) -> Result<Imported, ImportError> {
    let info = meta::read_info(dir)?;
    let mut dims = [0usize; 2];
    for (dim, key) in dims.iter_mut().zip([&cfg.state_key, &cfg.action_key]) {
        let feature = info
            .features
            .get(key.as_str())
            .ok_or_else(|| ImportError::MissingKey {
                path: info.path.clone(),
                key: key.clone(),
                found: info.features.keys().cloned().collect(),
            })?;
        *dim = feature.shape.iter().product();
        if *dim == 0 || matches!(feature.dtype.as_str(), "image" | "video" | "string") {
            return Err(ImportError::Metadata {
                path: info.path.clone(),
                field: format!("features.{key}"),
                expected: format!(
                    "numbers of a non-empty shape, found dtype {} shape {:?}",
                    feature.dtype, feature.shape
                ),
            });
        }
    }
    let [obs_dim, action_dim] = dims;
    let files = meta::data_files(dir, info.layout)?;
    let columns = [
        cfg.state_key.as_str(),
        cfg.action_key.as_str(),
        "episode_index",
        "frame_index",
        "timestamp",
    ];
    let mut episodes: BTreeMap<i64, Vec<Frame>> = BTreeMap::new();
    for (file, path) in files.iter().enumerate() {
        let t = table::read(path, &columns)?;
        for (row, cells) in t.rows.into_iter().enumerate() {
            let wrong = |column: &str, cell: &table::Cell, expected: &str| ImportError::Metadata {
                path: t.path.clone(),
                field: format!("{column} (row {row})"),
                expected: format!("{expected}, found {}", cell.kind()),
            };
            let [state, action, episode, index, timestamp]: [table::Cell; 5] =
                cells.try_into().expect("one cell per column");
            let e = episode
                .int()
                .ok_or_else(|| wrong("episode_index", &episode, "an integer"))?;
            let i = index
                .int()
                .ok_or_else(|| wrong("frame_index", &index, "an integer"))?;
            let ts = timestamp
                .num()
                .ok_or_else(|| wrong("timestamp", &timestamp, "a number of seconds"))?;
            let s = state
                .clone()
                .vector()
                .ok_or_else(|| wrong(&cfg.state_key, &state, "a list of numbers"))?;
            let a = action
                .clone()
                .vector()
                .ok_or_else(|| wrong(&cfg.action_key, &action, "a list of numbers"))?;
            episodes.entry(e).or_default().push(Frame {
                index: i,
                timestamp: ts,
                state: s,
                action: a,
                file,
            });
        }
    }
    let lengths = meta::episode_lengths(dir, info.layout)?;
    let mut dataset = Dataset {
        obs: Vec::new(),
        action: Vec::new(),
        episode_ends: Vec::new(),
        obs_dim,
        action_dim,
        task: cfg.task.clone().unwrap_or_else(|| dir_name(dir)),
        dt: (1.0 / info.fps) as f32,
        source: format!("lerobot {} {}", info.version, dir.display()),
        action_before_start: cfg.action_before_start,
        extra: BTreeMap::new(),
    };
    let keys = [(&cfg.state_key, obs_dim), (&cfg.action_key, action_dim)];
    for (&episode, frames) in &mut episodes {
        frames.sort_by_key(|f| f.index);
        check_episode(episode, frames, &files, &keys, &info, cfg)?;
        if let Some((path, lengths)) = &lengths {
            let listed = lengths.get(&episode).copied();
            if listed != Some(frames.len() as u64) {
                return Err(ImportError::RaggedEpisode {
                    path: path.clone(),
                    episode,
                    problem: format!(
                        "{} frames in data/, the episodes metadata lists {}",
                        frames.len(),
                        listed.map_or("no such episode".into(), |l| format!("{l}"))
                    ),
                });
            }
        }
        for f in frames.iter() {
            dataset.obs.extend(f.state.iter().map(|&v| v as f32));
            dataset.action.extend(f.action.iter().map(|&v| v as f32));
        }
        dataset.episode_ends.push(dataset.len() as i64);
    }
    check_totals(&info, &episodes, lengths.as_ref())?;
    let ignored = info
        .features
        .iter()
        .filter(|(k, _)| !columns.contains(&k.as_str()) && !INDEX_COLUMNS.contains(&k.as_str()))
        .map(|(k, f)| format!("{k} ({})", f.dtype))
        .collect();
    dataset.extra = BTreeMap::from([
        ("lerobot_dataset".into(), dir.display().to_string()),
        ("lerobot_version".into(), info.version.clone()),
        ("fps".into(), info.fps.to_string()),
        ("episodes".into(), episodes.len().to_string()),
        ("state_key".into(), cfg.state_key.clone()),
        ("action_key".into(), cfg.action_key.clone()),
    ]);
    Ok(Imported {
        dataset,
        version: info.version,
        layout: info.layout,
        fps: info.fps,
        files: files.len(),
        ignored,
        episodes_checked: lengths.is_some(),
    })
}

/// LeRobot's bookkeeping columns, read or deliberately skipped (not "ignored features").
const INDEX_COLUMNS: [&str; 2] = ["index", "task_index"];

fn dir_name(dir: &Path) -> String {
    dir.canonicalize()
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .filter(|n| !n.is_empty())
        .unwrap_or_else(|| "lerobot".into())
}

/// Frames `0..n` in order, vectors of the announced lengths and finite, timestamp steps of
/// 1 / fps.
fn check_episode(
    episode: i64,
    frames: &[Frame],
    files: &[PathBuf],
    keys: &[(&String, usize); 2],
    info: &meta::Info,
    cfg: &ImportConfig,
) -> Result<(), ImportError> {
    let period = 1.0 / info.fps;
    for (position, f) in frames.iter().enumerate() {
        let path = files[f.file].clone();
        let ragged = |problem: String| ImportError::RaggedEpisode {
            path: path.clone(),
            episode,
            problem,
        };
        if f.index != position as i64 {
            return Err(ragged(if position == 0 {
                format!("its first frame_index is {}, expected 0", f.index)
            } else if f.index == frames[position - 1].index {
                format!("frame_index {} appears twice", f.index)
            } else {
                format!(
                    "frame_index {} follows {} (frames missing)",
                    f.index,
                    frames[position - 1].index
                )
            }));
        }
        for ((key, dim), values) in keys.iter().zip([&f.state, &f.action]) {
            if values.len() != *dim {
                return Err(ragged(format!(
                    "frame {}: `{key}` has {} values, info.json's shape has {dim}",
                    f.index,
                    values.len()
                )));
            }
            if let Some(element) = values.iter().position(|v| !v.is_finite()) {
                return Err(ImportError::NonFinite {
                    path,
                    key: key.to_string(),
                    episode,
                    frame: f.index,
                    element,
                    value: values[element],
                });
            }
        }
        if position > 0 {
            let step = f.timestamp - frames[position - 1].timestamp;
            if !((step - period).abs() <= cfg.fps_tolerance) {
                return Err(ImportError::FpsMismatch {
                    path,
                    episode,
                    frame: f.index,
                    fps: info.fps,
                    step,
                    tolerance: cfg.fps_tolerance,
                });
            }
        }
    }
    Ok(())
}

/// `total_episodes` and `total_frames` of info.json against what data/ holds, and every episode
/// of the episodes metadata present in data/.
fn check_totals(
    info: &meta::Info,
    episodes: &BTreeMap<i64, Vec<Frame>>,
    lengths: Option<&(PathBuf, BTreeMap<i64, u64>)>,
) -> Result<(), ImportError> {
    let frames: usize = episodes.values().map(Vec::len).sum();
    for (field, total, found) in [
        ("total_episodes", info.total_episodes, episodes.len()),
        ("total_frames", info.total_frames, frames),
    ] {
        if total.is_some_and(|t| t != found as u64) {
            return Err(ImportError::Metadata {
                path: info.path.clone(),
                field: field.into(),
                expected: format!("{found} (what data/ holds), found {}", total.unwrap_or(0)),
            });
        }
    }
    if let Some((path, lengths)) = lengths {
        if let Some(missing) = lengths.keys().find(|e| !episodes.contains_key(e)) {
            return Err(ImportError::RaggedEpisode {
                path: path.clone(),
                episode: *missing,
                problem: "listed in the episodes metadata but has no frames in data/".into(),
            });
        }
    }
    Ok(())
}
