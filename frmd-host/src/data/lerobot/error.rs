//! The importer's errors: each names the file, the field or column, and what was expected.
use std::fmt;
use std::path::PathBuf;

/// Why a LeRobot dataset cannot be imported.
#[derive(Debug, Clone, PartialEq)]
pub enum ImportError {
    /// A file or directory the layout needs is missing or cannot be read.
    File { path: PathBuf, problem: String },
    /// A metadata field (`info.json`, the episodes metadata) is missing or has the wrong value.
    Metadata {
        path: PathBuf,
        field: String,
        expected: String,
    },
    /// A column (state, action, or one of the layout's index columns) is not in a data file, or
    /// a key is not among `info.json`'s features.
    MissingKey {
        path: PathBuf,
        key: String,
        found: Vec<String>,
    },
    /// An episode whose frames are not `0..n` in order, whose vectors change length, or whose
    /// length disagrees with the episodes metadata.
    RaggedEpisode {
        path: PathBuf,
        episode: i64,
        problem: String,
    },
    /// A NaN or infinite (or null) value in the state or action column.
    NonFinite {
        path: PathBuf,
        key: String,
        episode: i64,
        frame: i64,
        element: usize,
        value: f64,
    },
    /// Timestamps whose steps disagree with `1 / fps` beyond the tolerance.
    FpsMismatch {
        path: PathBuf,
        episode: i64,
        frame: i64,
        fps: f64,
        step: f64,
        tolerance: f64,
    },
    /// A data file the parquet reader cannot decode.
    Parquet { path: PathBuf, problem: String },
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImportError::File { path, problem } => write!(f, "{}: {problem}", path.display()),
            ImportError::Metadata {
                path,
                field,
                expected,
            } => write!(
                f,
                "{}: field `{field}`: expected {expected}",
                path.display()
            ),
            ImportError::MissingKey { path, key, found } => write!(
                f,
                "{}: missing key `{key}` (found: {}); choose another with --state-key or \
                 --action-key",
                path.display(),
                found.join(", ")
            ),
            ImportError::RaggedEpisode {
                path,
                episode,
                problem,
            } => write!(f, "{}: ragged episode {episode}: {problem}", path.display()),
            ImportError::NonFinite {
                path,
                key,
                episode,
                frame,
                element,
                value,
            } => write!(
                f,
                "{}: non-finite value {value} in `{key}` of episode {episode}, frame {frame}, \
                 element {element}",
                path.display()
            ),
            ImportError::FpsMismatch {
                path,
                episode,
                frame,
                fps,
                step,
                tolerance,
            } => write!(
                f,
                "{}: fps {fps} disagrees with the timestamps: episode {episode} steps {step} s \
                 before frame {frame}, expected {} s (tolerance {tolerance} s, --fps-tolerance)",
                path.display(),
                1.0 / fps
            ),
            ImportError::Parquet { path, problem } => {
                write!(
                    f,
                    "{}: not a readable parquet file: {problem}",
                    path.display()
                )
            }
        }
    }
}

impl std::error::Error for ImportError {}
