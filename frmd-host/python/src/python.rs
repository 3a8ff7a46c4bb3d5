//! The PyO3 classes over [`LocalPolicy`].
use frmd_host::diffusion::samplers::Solver;
use frmd_host::serve::{FloatType, LocalPolicy, ModelInfo, PolicySource, ServeConfig};
use numpy::ndarray::{Array2, Array3};
use numpy::{
    AllowTypeChange, IntoPyArray, PyArray2, PyArray3, PyArrayLikeDyn, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};

create_exception!(
    frmd,
    FrmdError,
    PyException,
    "An error of FRMD's loader or policy, with the Rust message."
);

fn frmd_error(e: impl std::fmt::Display) -> PyErr {
    FrmdError::new_err(e.to_string())
}

fn anyhow_error(e: anyhow::Error) -> PyErr {
    FrmdError::new_err(format!("{e:#}"))
}

/// The server settings of a load call (`frmd serve`'s options of the same names).
fn config(
    float64: bool,
    exec_steps: Option<u16>,
    dt: Option<f64>,
    init_action: Option<Vec<f64>>,
) -> ServeConfig {
    ServeConfig {
        float_type: if float64 {
            FloatType::F64
        } else {
            FloatType::F32
        },
        exec_steps,
        dt,
        init_action,
        zeros: false,
    }
}

fn source(path: PathBuf, steps: Option<usize>, solver: Option<&str>) -> PyResult<PolicySource> {
    let solver = solver
        .map(|s| s.parse::<Solver>())
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("solver: {e}")))?;
    PolicySource::detect(&path, steps, solver).map_err(anyhow_error)
}

/// `array` as `shape` values in row-major order (a flat array of the same length passes too).
fn values(
    array: &PyArrayLikeDyn<'_, f64, AllowTypeChange>,
    shape: &[usize],
    what: &str,
) -> PyResult<Vec<f64>> {
    let expected: usize = shape.iter().product();
    let got = array.shape();
    if got != shape && !(got.len() == 1 && got[0] == expected) {
        return Err(PyValueError::new_err(format!(
            "{what} has shape {got:?}, expected {shape:?} (or {expected} values flat)"
        )));
    }
    Ok(array.as_array().iter().copied().collect())
}

/// `executed` for the next ACT: as given, or `exec_steps` once the episode has had a chunk.
fn executed(given: Option<u32>, policy: &LocalPolicy) -> u32 {
    given.unwrap_or(if policy.has_chunk() {
        u32::from(policy.info().exec_steps)
    } else {
        0
    })
}

fn lock(policies: &Mutex<Vec<LocalPolicy>>) -> PyResult<MutexGuard<'_, Vec<LocalPolicy>>> {
    policies
        .lock()
        .map_err(|_| FrmdError::new_err("the policy was poisoned by a panic in another thread"))
}

/// `n` policies with the shared announcement.
struct Loaded {
    info: ModelInfo,
    policies: Mutex<Vec<LocalPolicy>>,
    last_policy_ns: Mutex<u64>,
}

impl Loaded {
    fn load(py: Python<'_>, n: usize, source: PolicySource, cfg: ServeConfig) -> PyResult<Self> {
        if n == 0 {
            return Err(PyValueError::new_err(
                "batch must be at least 1 (batch=1: one episode)",
            ));
        }
        let policies = py
            .detach(|| {
                (0..n)
                    .map(|_| LocalPolicy::load(&source, &cfg))
                    .collect::<anyhow::Result<Vec<_>>>()
            })
            .map_err(anyhow_error)?;
        Ok(Loaded {
            info: policies[0].info().clone(),
            policies: Mutex::new(policies),
            last_policy_ns: Mutex::new(0),
        })
    }

    fn dims(&self) -> (usize, usize, usize, usize) {
        let i = &self.info;
        (
            usize::from(i.obs_history),
            usize::from(i.obs_dim),
            usize::from(i.horizon),
            usize::from(i.action_dim),
        )
    }

    fn reset(&self, py: Python<'_>, seeds: &[u64], init: Vec<Vec<f64>>) -> PyResult<()> {
        py.detach(|| -> PyResult<()> {
            let mut policies = lock(&self.policies)?;
            for ((policy, &seed), init) in policies.iter_mut().zip(seeds).zip(init) {
                policy.reset(seed, init).map_err(frmd_error)?;
            }
            Ok(())
        })
    }

    /// One chunk per policy; `obs` holds `n` histories back to back.
    fn act(
        &self,
        py: Python<'_>,
        obs: Vec<f64>,
        executed_each: &[Option<u32>],
    ) -> PyResult<Vec<f64>> {
        let (m, o, _, _) = self.dims();
        let (actions, policy_ns) = py.detach(|| -> PyResult<(Vec<f64>, u64)> {
            let mut policies = lock(&self.policies)?;
            let mut actions = Vec::new();
            let mut policy_ns = 0;
            for ((policy, obs), &given) in policies
                .iter_mut()
                .zip(obs.chunks_exact(m * o))
                .zip(executed_each)
            {
                let done = executed(given, policy);
                let chunk = policy.act(done, obs.to_vec()).map_err(frmd_error)?;
                policy_ns += chunk.policy_ns;
                actions.extend_from_slice(&chunk.actions);
            }
            Ok((actions, policy_ns))
        })?;
        *self
            .last_policy_ns
            .lock()
            .map_err(|_| FrmdError::new_err("poisoned"))? = policy_ns;
        Ok(actions)
    }
}

/// An FRMD policy as `frmd serve` serves it, one episode (or `batch` independent episodes for
/// vectorized environments): `reset(seed)` starts an episode, `act(obs)` returns the next chunk.
#[pyclass(module = "frmd", frozen)]
struct Policy(Loaded);

impl Policy {
    /// The environments, refusing a batch method on a single policy and the reverse.
    fn batch_of(&self, batched: bool) -> PyResult<usize> {
        let n = lock(&self.0.policies)?.len();
        match (batched, n) {
            (false, 1) | (true, _) => Ok(n),
            (false, n) => Err(PyValueError::new_err(format!(
                "this policy was loaded with batch={n}: use reset_batch and act_batch"
            ))),
        }
    }
}

#[pymethods]
impl Policy {
    /// Loads a blob file, a baked export directory or a checkpoint directory (told apart by what
    /// `path` holds), `batch` times. `steps`/`solver`: a checkpoint's sampler; `exec_steps`,
    /// `dt`, `init_action`, `float64`: as `frmd serve`'s `--exec-steps`, `--dt`,
    /// `--init-action`, `--float f64`.
    #[staticmethod]
    #[pyo3(signature = (path, *, batch=1, steps=None, solver=None, exec_steps=None, dt=None, init_action=None, float64=false))]
    #[allow(clippy::too_many_arguments)]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        batch: usize,
        steps: Option<usize>,
        solver: Option<&str>,
        exec_steps: Option<u16>,
        dt: Option<f64>,
        init_action: Option<Vec<f64>>,
        float64: bool,
    ) -> PyResult<Self> {
        let source = source(path, steps, solver)?;
        let cfg = config(float64, exec_steps, dt, init_action);
        Ok(Policy(Loaded::load(py, batch, source, cfg)?))
    }

    /// Starts an episode: noise seeded by `seed`, `init_action` (`action_dim` values; default:
    /// the load's `init_action`, else zeros) as the previous action.
    #[pyo3(signature = (seed, init_action=None))]
    fn reset(&self, py: Python<'_>, seed: u64, init_action: Option<Vec<f64>>) -> PyResult<()> {
        self.batch_of(false)?;
        self.0
            .reset(py, &[seed], vec![init_action.unwrap_or_default()])
    }

    /// The next chunk, `(horizon, action_dim)` float64, for `obs` of shape `(obs_history,
    /// obs_dim)` (oldest first). `executed`: actions of the previous chunk that were commanded
    /// (default: `exec_steps`, 0 for an episode's first chunk).
    #[pyo3(signature = (obs, executed=None))]
    fn act<'py>(
        &self,
        py: Python<'py>,
        obs: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
        executed: Option<u32>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.batch_of(false)?;
        let (m, o, h, k) = self.0.dims();
        let obs = values(&obs, &[m, o], "obs")?;
        let actions = self.0.act(py, obs, &[executed])?;
        let chunk = Array2::from_shape_vec((h, k), actions).map_err(frmd_error)?;
        Ok(chunk.into_pyarray(py))
    }

    /// Starts every episode of a batch: `seeds` (`batch` values), `init_actions` (`(batch,
    /// action_dim)`; default: the load's `init_action`, else zeros).
    #[pyo3(signature = (seeds, init_actions=None))]
    fn reset_batch<'py>(
        &self,
        py: Python<'py>,
        seeds: Vec<u64>,
        init_actions: Option<PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
    ) -> PyResult<()> {
        let n = self.batch_of(true)?;
        if seeds.len() != n {
            return Err(PyValueError::new_err(format!(
                "{} seeds for batch={n}",
                seeds.len()
            )));
        }
        let k = usize::from(self.0.info.action_dim);
        let init = match init_actions {
            None => vec![Vec::new(); n],
            Some(a) => values(&a, &[n, k], "init_actions")?
                .chunks(k.max(1))
                .map(<[f64]>::to_vec)
                .collect(),
        };
        self.0.reset(py, &seeds, init)
    }

    /// The next chunk of every episode, `(batch, horizon, action_dim)`, for `obs` of shape
    /// `(batch, obs_history, obs_dim)`. `executed`: one count for all, `batch` counts, or the
    /// default of [`Policy::act`] for each.
    #[pyo3(signature = (obs, executed=None))]
    fn act_batch<'py>(
        &self,
        py: Python<'py>,
        obs: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
        executed: Option<Vec<u32>>,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let n = self.batch_of(true)?;
        let (m, o, h, k) = self.0.dims();
        let obs = values(&obs, &[n, m, o], "obs")?;
        let executed: Vec<Option<u32>> = match executed {
            None => vec![None; n],
            Some(e) if e.len() == 1 => vec![Some(e[0]); n],
            Some(e) if e.len() == n => e.into_iter().map(Some).collect(),
            Some(e) => {
                return Err(PyValueError::new_err(format!(
                    "{} executed counts for batch={n}",
                    e.len()
                )))
            }
        };
        let actions = self.0.act(py, obs, &executed)?;
        let chunks = Array3::from_shape_vec((n, h, k), actions).map_err(frmd_error)?;
        Ok(chunks.into_pyarray(py))
    }

    /// Independent episodes (1 unless loaded with `batch`).
    #[getter]
    fn batch(&self) -> PyResult<usize> {
        self.batch_of(true)
    }
    /// Observation values per step.
    #[getter]
    fn obs_dim(&self) -> u16 {
        self.0.info.obs_dim
    }
    /// Action values per step (degrees of freedom).
    #[getter]
    fn action_dim(&self) -> u16 {
        self.0.info.action_dim
    }
    /// Observations per call (the history, oldest first).
    #[getter]
    fn obs_history(&self) -> u16 {
        self.0.info.obs_history
    }
    /// Actions per chunk.
    #[getter]
    fn horizon(&self) -> u16 {
        self.0.info.horizon
    }
    /// Actions to execute per chunk; `act`'s default `executed` after the first chunk.
    #[getter]
    fn exec_steps(&self) -> u16 {
        self.0.info.exec_steps
    }
    /// Whether values are handled as f64 (`float64=True`, `frmd serve --float f64`); otherwise
    /// observations are rounded to f32 as the f32 wire would carry them.
    #[getter]
    fn float64(&self) -> bool {
        self.0.info.float_type == FloatType::F64
    }
    /// Control period in seconds (0: unknown; the previous action's rate is then 0).
    #[getter]
    fn dt(&self) -> f64 {
        self.0.info.dt
    }
    /// What is served (kind and path).
    #[getter]
    fn name(&self) -> String {
        self.0.info.name.clone()
    }
    /// Wall time of the last `act`'s policy calls in nanoseconds (summed over a batch).
    #[getter]
    fn last_policy_ns(&self) -> PyResult<u64> {
        Ok(*self
            .0
            .last_policy_ns
            .lock()
            .map_err(|_| FrmdError::new_err("poisoned"))?)
    }

    fn __repr__(&self) -> String {
        let i = &self.0.info;
        format!(
            "frmd.Policy({:?}, obs {}x{}, horizon {}, action_dim {}, exec_steps {}, dt {})",
            i.name, i.obs_history, i.obs_dim, i.horizon, i.action_dim, i.exec_steps, i.dt
        )
    }
}

#[pymodule]
#[pyo3(name = "frmd")]
fn frmd_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Policy>()?;
    m.add("FrmdError", m.py().get_type::<FrmdError>())?;
    Ok(())
}
