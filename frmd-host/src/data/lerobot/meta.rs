//! The metadata of a LeRobot dataset: `meta/info.json` (version, fps, features, totals), the
//! episodes' lengths (`meta/episodes.jsonl` in v2.x, `meta/episodes/**/*.parquet` in v3.0) and
//! where the frames are (`data/chunk-*/episode_*.parquet` or `data/chunk-*/file-*.parquet`).
use super::error::ImportError;
use super::table;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The two layouts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// LeRobotDataset v2.0 / v2.1: one parquet file per episode, episodes in JSON lines.
    V2,
    /// LeRobotDataset v3.0: many episodes per parquet file, episodes in parquet.
    V3,
}

/// One entry of `info.json`'s `features`.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Feature {
    pub dtype: String,
    pub shape: Vec<usize>,
}

/// What the importer reads from `meta/info.json`.
pub(super) struct Info {
    pub path: PathBuf,
    pub version: String,
    pub layout: Layout,
    pub fps: f64,
    pub total_episodes: Option<u64>,
    pub total_frames: Option<u64>,
    pub features: BTreeMap<String, Feature>,
}

fn metadata(path: &Path, field: &str, expected: impl Into<String>) -> ImportError {
    ImportError::Metadata {
        path: path.to_path_buf(),
        field: field.to_string(),
        expected: expected.into(),
    }
}

fn read_text(path: &Path) -> Result<String, ImportError> {
    std::fs::read_to_string(path).map_err(|e| ImportError::File {
        path: path.to_path_buf(),
        problem: format!("cannot read: {e}"),
    })
}

/// Reads and checks `dir/meta/info.json`.
pub(super) fn read_info(dir: &Path) -> Result<Info, ImportError> {
    let path = dir.join("meta").join("info.json");
    let json: Value = serde_json::from_str(&read_text(&path)?)
        .map_err(|e| metadata(&path, "(the whole file)", format!("a JSON object ({e})")))?;
    let version = json["codebase_version"]
        .as_str()
        .ok_or_else(|| metadata(&path, "codebase_version", "a string such as \"v2.1\""))?
        .to_string();
    let layout = match version.as_str() {
        "v2.0" | "v2.1" => Layout::V2,
        "v3.0" => Layout::V3,
        other => {
            return Err(metadata(
                &path,
                "codebase_version",
                format!("\"v2.0\", \"v2.1\" or \"v3.0\", found {other:?}"),
            ))
        }
    };
    let fps = json["fps"]
        .as_f64()
        .filter(|f| f.is_finite() && *f > 0.0)
        .ok_or_else(|| {
            metadata(
                &path,
                "fps",
                format!("a positive number, found {}", json["fps"]),
            )
        })?;
    let object = json["features"]
        .as_object()
        .ok_or_else(|| metadata(&path, "features", "an object of feature descriptions"))?;
    let mut features = BTreeMap::new();
    for (key, value) in object {
        let field = format!("features.{key}");
        let dtype = value["dtype"]
            .as_str()
            .ok_or_else(|| metadata(&path, &format!("{field}.dtype"), "a string"))?;
        let shape = value["shape"]
            .as_array()
            .and_then(|dims| {
                dims.iter()
                    .map(|d| d.as_u64().map(|d| d as usize))
                    .collect()
            })
            .ok_or_else(|| metadata(&path, &format!("{field}.shape"), "a list of sizes"))?;
        features.insert(
            key.clone(),
            Feature {
                dtype: dtype.to_string(),
                shape,
            },
        );
    }
    Ok(Info {
        total_episodes: json["total_episodes"].as_u64(),
        total_frames: json["total_frames"].as_u64(),
        path,
        version,
        layout,
        fps,
        features,
    })
}

/// The `.parquet` files of `dir/*` (sorted), for the chunk directories of `data/` and
/// `meta/episodes/`, whose names start with `prefix`.
fn chunk_files(root: &Path, prefix: &str) -> Result<Vec<PathBuf>, ImportError> {
    let list = |dir: &Path| -> Result<Vec<PathBuf>, ImportError> {
        let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|e| ImportError::File {
                path: dir.to_path_buf(),
                problem: format!("cannot list: {e}"),
            })?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .collect();
        out.sort();
        Ok(out)
    };
    let mut files = Vec::new();
    for chunk in list(root)? {
        let is_chunk = chunk.is_dir()
            && chunk
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("chunk-"));
        if !is_chunk {
            continue;
        }
        files.extend(list(&chunk)?.into_iter().filter(|f| {
            let name = f.file_name().unwrap_or_default().to_string_lossy();
            name.starts_with(prefix) && name.ends_with(".parquet")
        }));
    }
    Ok(files)
}

/// The data files of the layout, in order; none is an error naming the pattern.
pub(super) fn data_files(dir: &Path, layout: Layout) -> Result<Vec<PathBuf>, ImportError> {
    let prefix = match layout {
        Layout::V2 => "episode_",
        Layout::V3 => "file-",
    };
    let root = dir.join("data");
    let files = chunk_files(&root, prefix)?;
    if files.is_empty() {
        return Err(ImportError::File {
            path: root,
            problem: format!("no data files chunk-*/{prefix}*.parquet"),
        });
    }
    Ok(files)
}

/// Episode lengths from the episodes metadata, with the file they came from; `None` when the
/// dataset has no episodes metadata.
pub(super) fn episode_lengths(
    dir: &Path,
    layout: Layout,
) -> Result<Option<(PathBuf, BTreeMap<i64, u64>)>, ImportError> {
    let mut lengths = BTreeMap::new();
    match layout {
        Layout::V2 => {
            let path = dir.join("meta").join("episodes.jsonl");
            if !path.exists() {
                return Ok(None);
            }
            for (line_no, line) in read_text(&path)?.lines().enumerate() {
                if line.trim().is_empty() {
                    continue;
                }
                let field = |name: &str| format!("{name} (line {})", line_no + 1);
                let json: Value = serde_json::from_str(line).map_err(|e| {
                    metadata(&path, &field("(line)"), format!("a JSON object ({e})"))
                })?;
                let episode = json["episode_index"]
                    .as_i64()
                    .ok_or_else(|| metadata(&path, &field("episode_index"), "an integer"))?;
                let length = json["length"]
                    .as_u64()
                    .ok_or_else(|| metadata(&path, &field("length"), "a frame count"))?;
                lengths.insert(episode, length);
            }
            Ok(Some((path, lengths)))
        }
        Layout::V3 => {
            let root = dir.join("meta").join("episodes");
            if !root.is_dir() {
                return Ok(None);
            }
            for path in chunk_files(&root, "file-")? {
                let t = table::read(&path, &["episode_index", "length"])?;
                for (row, cells) in t.rows.iter().enumerate() {
                    let field = |name: &str| format!("{name} (row {row})");
                    let episode = cells[0]
                        .int()
                        .ok_or_else(|| metadata(&path, &field("episode_index"), "an integer"))?;
                    let length = cells[1]
                        .int()
                        .and_then(|l| u64::try_from(l).ok())
                        .ok_or_else(|| metadata(&path, &field("length"), "a frame count"))?;
                    lengths.insert(episode, length);
                }
            }
            Ok(Some((root, lengths)))
        }
    }
}
