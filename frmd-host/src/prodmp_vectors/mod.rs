//! Reference vectors for the ProDMP decoder (schema of `frmd-core/tests/data/prodmp_vectors.json`,
//! produced from mp_pytorch 0.1.4 in float64): parsing, validation and the f64/f32 check.
//!
//! Schema: `{ "cases": [case..], ..metadata }` with, per case, `name`, `config` (mp_pytorch
//! ProDMP settings), `inputs` (`params` DoF-major `[w_0..w_{b-1}, g]` per DoF, `init_time` s,
//! `init_pos`, `init_vel` units/s) and `queries` (`times` s, `pos`/`vel` `[num_times][num_dof]`,
//! optional `pos_H_unscaled` `[num_times][num_basis+1]`). Optional `derived` values (centres,
//! bandwidths, grid size, table maxima, scales) are checked when present.
//!
//! Every problem is a [`VectorsError`] naming the case and field; nothing here panics.
//!
//! Note: serde_json (without its `float_roundtrip` feature, which would rebuild candle's
//! dependencies) may parse a 17-digit decimal 1 ulp off. That is far below every tolerance, but a
//! time written exactly at the end of the pre-computed range (`delay + 6 tau`) can then land just
//! beyond it and be reported as out of range.
pub(crate) mod check;

use frmd_core::prodmp::ProDmpError;
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};

pub use check::{check_case, CaseReport, Tolerances};

/// A whole vectors file.
#[derive(Clone, Debug, Deserialize)]
pub struct VectorsFile {
    /// Library the vectors come from (informational), e.g. "mp_pytorch 0.1.4".
    #[serde(default)]
    pub library: Option<String>,
    pub cases: Vec<Case>,
}

#[derive(Clone, Debug, Deserialize)]
pub struct Case {
    pub name: String,
    #[serde(default)]
    pub note: Option<String>,
    pub config: CaseConfig,
    #[serde(default)]
    pub derived: Option<Derived>,
    pub inputs: Inputs,
    pub queries: Vec<Query>,
}

/// Either one scalar or one value per basis (mp_pytorch accepts both for `weights_scale`).
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum ScaleSpec {
    Scalar(f64),
    PerBasis(Vec<f64>),
}

fn default_length_factor() -> usize {
    frmd_core::prodmp::PRE_COMPUTE_LENGTH_FACTOR
}

fn default_scale() -> ScaleSpec {
    ScaleSpec::Scalar(1.0)
}

fn default_one() -> f64 {
    1.0
}

/// mp_pytorch ProDMP settings of one case.
#[derive(Clone, Debug, Deserialize)]
pub struct CaseConfig {
    #[serde(default)]
    pub mp_type: Option<String>,
    #[serde(default)]
    pub phase_generator: Option<String>,
    pub num_dof: usize,
    pub tau: f64,
    pub delay: f64,
    pub alpha_phase: f64,
    pub num_basis: usize,
    pub basis_bandwidth_factor: f64,
    #[serde(default)]
    pub num_basis_outside: usize,
    pub dt: f64,
    pub alpha: f64,
    #[serde(default = "default_length_factor")]
    pub pre_compute_length_factor: usize,
    #[serde(default = "default_scale")]
    pub weights_scale: ScaleSpec,
    #[serde(default = "default_one")]
    pub goal_scale: f64,
    #[serde(default)]
    pub relative_goal: bool,
    #[serde(default)]
    pub auto_scale_basis: bool,
    #[serde(default)]
    pub disable_weights: bool,
    #[serde(default)]
    pub disable_goal: bool,
    #[serde(default)]
    pub learn_tau: bool,
    #[serde(default)]
    pub learn_delay: bool,
    #[serde(default)]
    pub dtype: Option<String>,
}

/// Intermediate values of the reference (all optional).
#[derive(Clone, Debug, Default, Deserialize)]
pub struct Derived {
    #[serde(default)]
    pub num_pre_compute: Option<usize>,
    #[serde(default)]
    pub centers_phase: Option<Vec<f64>>,
    #[serde(default)]
    pub bandwidth: Option<Vec<f64>>,
    #[serde(default)]
    pub weights_goal_scale: Option<Vec<f64>>,
    #[serde(default)]
    pub pc_pos_basis_max: Option<Vec<f64>>,
}

#[derive(Clone, Debug, Deserialize)]
pub struct Inputs {
    /// DoF-major parameters; per DoF `[w_0..w_{b-1}, g]` (only `g` with `disable_weights`, only
    /// the weights with `disable_goal`).
    pub params: Vec<f64>,
    pub init_time: f64,
    pub init_pos: Vec<f64>,
    pub init_vel: Vec<f64>,
}

#[derive(Clone, Debug, Deserialize)]
pub struct Query {
    pub times: Vec<f64>,
    pub pos: Vec<Vec<f64>>,
    pub vel: Vec<Vec<f64>>,
    #[serde(default, rename = "pos_H_unscaled")]
    pub pos_h_unscaled: Option<Vec<Vec<f64>>>,
}

/// Why a vectors file cannot be used. Variants name the case (index and name) and field.
#[derive(Debug)]
pub enum VectorsError {
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Not JSON, or JSON not in the schema (missing field, wrong type, NaN/Infinity tokens...).
    Malformed {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// The file has no cases.
    NoCases,
    /// A number that must be finite is NaN or infinite.
    NonFinite { case: String, field: String },
    /// An array has the wrong length.
    WrongLength {
        case: String,
        field: String,
        expected: usize,
        found: usize,
    },
    /// The case asks for something outside mp_pytorch ProDMP with an exponential phase.
    Unsupported { case: String, what: String },
    /// The config is rejected by the decoder.
    Config { case: String, error: ProDmpError },
}

impl fmt::Display for VectorsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io { path, source } => write!(f, "cannot read {}: {source}", path.display()),
            Self::Malformed { path, source } => write!(
                f,
                "{} is not a ProDMP vectors file (JSON with \"cases\" in the schema of \
                 frmd-core/tests/data/prodmp_vectors.json; NaN/Infinity are not allowed): {source}",
                path.display()
            ),
            Self::NoCases => write!(f, "vectors file has no cases"),
            Self::NonFinite { case, field } => {
                write!(f, "case {case}: {field} contains a NaN or infinite value")
            }
            Self::WrongLength {
                case,
                field,
                expected,
                found,
            } => {
                write!(
                    f,
                    "case {case}: {field} has length {found}, expected {expected}"
                )
            }
            Self::Unsupported { case, what } => write!(f, "case {case}: unsupported {what}"),
            Self::Config { case, error } => write!(f, "case {case}: invalid config: {error}"),
        }
    }
}

impl std::error::Error for VectorsError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            Self::Malformed { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// Reads, parses and validates a vectors file.
pub fn load(path: &Path) -> Result<VectorsFile, VectorsError> {
    let text = std::fs::read_to_string(path).map_err(|source| VectorsError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, path)
}

/// Parses and validates vectors from `text` (`path` only names the source in errors).
pub fn parse(text: &str, path: &Path) -> Result<VectorsFile, VectorsError> {
    let file: VectorsFile =
        serde_json::from_str(text).map_err(|source| VectorsError::Malformed {
            path: path.to_path_buf(),
            source,
        })?;
    if file.cases.is_empty() {
        return Err(VectorsError::NoCases);
    }
    for (index, case) in file.cases.iter().enumerate() {
        case.validate(index)?;
    }
    Ok(file)
}

fn finite(case: &str, field: &str, values: &[f64]) -> Result<(), VectorsError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(VectorsError::NonFinite {
            case: case.to_string(),
            field: field.to_string(),
        })
    }
}

fn length(case: &str, field: &str, expected: usize, found: usize) -> Result<(), VectorsError> {
    if expected == found {
        Ok(())
    } else {
        Err(VectorsError::WrongLength {
            case: case.to_string(),
            field: field.to_string(),
            expected,
            found,
        })
    }
}

fn matrix(
    case: &str,
    field: &str,
    rows: &[Vec<f64>],
    num_rows: usize,
    num_cols: usize,
) -> Result<(), VectorsError> {
    length(case, field, num_rows, rows.len())?;
    for (index, row) in rows.iter().enumerate() {
        let name = format!("{field}[{index}]");
        length(case, &name, num_cols, row.len())?;
        finite(case, &name, row)?;
    }
    Ok(())
}

impl Case {
    /// `#index name` as used in messages.
    pub fn label(&self, index: usize) -> String {
        format!("#{index} {}", self.name)
    }

    /// Number of parameters per DoF as stored in `inputs.params` (disabled parts are absent).
    pub fn stored_params_per_dof(&self) -> usize {
        let c = &self.config;
        match (c.disable_weights, c.disable_goal) {
            (true, _) => 1,
            (false, true) => c.num_basis,
            (false, false) => c.num_basis + 1,
        }
    }

    /// Checks the case against the schema: supported options, finite numbers, array lengths.
    pub fn validate(&self, index: usize) -> Result<(), VectorsError> {
        let label = self.label(index);
        let c = &self.config;
        let unsupported = |what: String| {
            Err(VectorsError::Unsupported {
                case: label.clone(),
                what,
            })
        };
        if let Some(mp_type) = &c.mp_type {
            if mp_type != "prodmp" {
                return unsupported(format!("mp_type {mp_type:?} (only \"prodmp\")"));
            }
        }
        if let Some(phase) = &c.phase_generator {
            if phase != "ExpDecayPhaseGenerator" {
                return unsupported(format!("phase_generator {phase:?}"));
            }
        }
        if c.learn_tau || c.learn_delay {
            return unsupported(
                "learn_tau/learn_delay (parameters would include tau/delay)".into(),
            );
        }
        if c.disable_weights && c.disable_goal {
            return unsupported("disable_weights together with disable_goal".into());
        }
        let scalars = [
            c.tau,
            c.delay,
            c.alpha_phase,
            c.basis_bandwidth_factor,
            c.dt,
            c.alpha,
            c.goal_scale,
        ];
        finite(&label, "config", &scalars)?;
        if let ScaleSpec::PerBasis(scales) = &c.weights_scale {
            length(&label, "config.weights_scale", c.num_basis, scales.len())?;
            finite(&label, "config.weights_scale", scales)?;
        } else if let ScaleSpec::Scalar(scale) = &c.weights_scale {
            finite(&label, "config.weights_scale", &[*scale])?;
        }
        let inputs = &self.inputs;
        let params_len = c
            .num_dof
            .checked_mul(self.stored_params_per_dof())
            .ok_or_else(|| VectorsError::Unsupported {
                case: label.clone(),
                what: "num_dof * num_params overflows".into(),
            })?;
        length(&label, "inputs.params", params_len, inputs.params.len())?;
        finite(&label, "inputs.params", &inputs.params)?;
        finite(&label, "inputs.init_time", &[inputs.init_time])?;
        length(&label, "inputs.init_pos", c.num_dof, inputs.init_pos.len())?;
        finite(&label, "inputs.init_pos", &inputs.init_pos)?;
        length(&label, "inputs.init_vel", c.num_dof, inputs.init_vel.len())?;
        finite(&label, "inputs.init_vel", &inputs.init_vel)?;
        if self.queries.is_empty() {
            return Err(VectorsError::WrongLength {
                case: label,
                field: "queries".into(),
                expected: 1,
                found: 0,
            });
        }
        for (q, query) in self.queries.iter().enumerate() {
            let n = query.times.len();
            finite(&label, &format!("queries[{q}].times"), &query.times)?;
            matrix(
                &label,
                &format!("queries[{q}].pos"),
                &query.pos,
                n,
                c.num_dof,
            )?;
            matrix(
                &label,
                &format!("queries[{q}].vel"),
                &query.vel,
                n,
                c.num_dof,
            )?;
            if let Some(h) = &query.pos_h_unscaled {
                matrix(
                    &label,
                    &format!("queries[{q}].pos_H_unscaled"),
                    h,
                    n,
                    c.num_basis + 1,
                )?;
            }
        }
        if let Some(derived) = &self.derived {
            let per_basis = [
                ("centers_phase", &derived.centers_phase, c.num_basis),
                ("bandwidth", &derived.bandwidth, c.num_basis),
            ];
            let per_param = [
                (
                    "weights_goal_scale",
                    &derived.weights_goal_scale,
                    c.num_basis + 1,
                ),
                (
                    "pc_pos_basis_max",
                    &derived.pc_pos_basis_max,
                    c.num_basis + 1,
                ),
            ];
            for (field, values, expected) in per_basis.into_iter().chain(per_param) {
                if let Some(values) = values {
                    length(&label, &format!("derived.{field}"), expected, values.len())?;
                    finite(&label, &format!("derived.{field}"), values)?;
                }
            }
        }
        Ok(())
    }
}
