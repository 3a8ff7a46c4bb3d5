//! [`Policy`]: observation history, last commanded action, sampling and un-normalization.

use super::history::ObsHistory;
use super::network::Network;
use super::normalize::RangeNormalizer;
use super::sampler::{Conditioning, Noise, Sampler, SamplerWork, Trajectory};
use super::{PolicyDims, PolicyError};

/// Everything baked besides the network.
#[derive(Clone, Copy, Debug)]
pub struct PolicyConfig<'a> {
    /// Observation history length `m` (the other sizes are those of the tables below).
    pub history: usize,
    /// Observation normalization (raw units), `o` dimensions.
    pub obs_norm: RangeNormalizer<'a>,
    /// Action normalization (raw units), `k` dimensions.
    pub action_norm: RangeNormalizer<'a>,
    /// Step table, decoder (`n` query times, `p` parameters per DoF), input layout, control
    /// period.
    pub sampler: Sampler<'a>,
}

impl PolicyConfig<'_> {
    /// The policy's sizes.
    pub fn dims(&self) -> PolicyDims {
        PolicyDims {
            history: self.history,
            obs_dim: self.obs_norm.len(),
            action_dim: self.action_norm.len(),
            horizon: self.sampler.decoder.horizon(),
            params_per_dof: self.sampler.decoder.params_per_dof(),
        }
    }
}

/// A policy over network `Net` with room for a history of `M` observations of `O` values, `K`
/// DoFs, horizon `N`, `P` ProDMP parameters per DoF and a model input of `I` values (the sizes of
/// its [`PolicyConfig`] may be smaller, heapless style: a firmware image bakes them exactly, a
/// host runs any exported shape up to its capacities); see the [module docs](super) for the call
/// sequence.
#[derive(Clone, Debug)]
pub struct Policy<
    'a,
    Net,
    const M: usize,
    const O: usize,
    const K: usize,
    const N: usize,
    const P: usize,
    const I: usize,
> {
    config: PolicyConfig<'a>,
    dims: PolicyDims,
    network: Net,
    history: ObsHistory<M, O>,
    history_ordered: [[f32; O]; M],
    /// Last commanded action, normalized; `None` before [`Policy::reset`].
    prev_action: Option<[f32; K]>,
    /// Its rate, normalized units per second.
    prev_rate: [f32; K],
    work: SamplerWork<K, N, P, I>,
    normalized: Trajectory<N, K>,
    chunk: Trajectory<N, K>,
    chunk_ready: bool,
    cursor: usize,
}

fn check_finite(values: &[f32]) -> Result<(), usize> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(index),
        None => Ok(()),
    }
}

impl<
        'a,
        Net: Network,
        const M: usize,
        const O: usize,
        const K: usize,
        const N: usize,
        const P: usize,
        const I: usize,
    > Policy<'a, Net, M, O, K, N, P, I>
{
    /// Validates `config` against `network` and the capacities (normalization, steps, decoder,
    /// layout widths, output width, noise-level variants) and builds the policy. Call
    /// [`Self::reset`] before the first chunk.
    pub fn new(config: PolicyConfig<'a>, network: Net) -> Result<Self, PolicyError> {
        config.obs_norm.validate()?;
        config.action_norm.validate()?;
        let dims = config.dims();
        config.sampler.decoder.validate()?;
        config.sampler.validate(&dims, &network)?;
        if network.input_width() > I {
            return Err(PolicyError::InputWidth);
        }
        if !dims.fits([M, O, K, N, P]) {
            return Err(PolicyError::Capacity);
        }
        let history =
            ObsHistory::with_sizes(dims.history, dims.obs_dim).ok_or(PolicyError::Capacity)?;
        Ok(Self {
            config,
            dims,
            network,
            history,
            history_ordered: [[0.0; O]; M],
            prev_action: None,
            prev_rate: [0.0; K],
            work: SamplerWork::new(),
            normalized: Trajectory::zeros(),
            chunk: Trajectory::zeros(),
            chunk_ready: false,
            cursor: 0,
        })
    }

    /// The policy's sizes.
    pub fn dims(&self) -> PolicyDims {
        self.dims
    }

    /// `values` if it holds `len` values, else [`PolicyError::InputWidth`].
    fn sized(values: &[f32], len: usize) -> Result<&[f32], PolicyError> {
        if values.len() == len {
            Ok(values)
        } else {
            Err(PolicyError::InputWidth)
        }
    }

    /// `raw` (`k` values) normalized with the action normalizer.
    fn normalized_action(&self, raw: &[f32]) -> Result<[f32; K], PolicyError> {
        let raw = Self::sized(raw, self.dims.action_dim)?;
        check_finite(raw).map_err(|index| PolicyError::NonFiniteAction { index })?;
        let mut normalized = [0.0; K];
        self.config.action_norm.normalize(raw, &mut normalized);
        Ok(normalized)
    }

    /// Starts an episode: forgets the observation history and the current chunk, and sets the
    /// last commanded action to `initial_action` (`k` raw values, e.g. the robot's current
    /// position) with rate 0.
    pub fn reset(&mut self, initial_action: &[f32]) -> Result<(), PolicyError> {
        self.prev_action = Some(self.normalized_action(initial_action)?);
        self.prev_rate = [0.0; K];
        self.history.clear();
        self.chunk_ready = false;
        self.cursor = 0;
        Ok(())
    }

    /// Pushes the newest observation (`o` raw values). NaN or infinite elements are rejected and
    /// the history is left unchanged.
    pub fn observe(&mut self, observation: &[f32]) -> Result<(), PolicyError> {
        let observation = Self::sized(observation, self.dims.obs_dim)?;
        check_finite(observation).map_err(|index| PolicyError::NonFiniteObservation { index })?;
        let mut normalized = [0.0; O];
        self.config.obs_norm.normalize(observation, &mut normalized);
        self.history.push(&normalized);
        Ok(())
    }

    /// Sets the last commanded action (raw units) and its rate (raw units per second), `k`
    /// values each, e.g. when the controller commands actions the policy did not emit.
    pub fn set_previous_action(&mut self, action: &[f32], rate: &[f32]) -> Result<(), PolicyError> {
        let normalized = self.normalized_action(action)?;
        let rate = Self::sized(rate, self.dims.action_dim)?;
        check_finite(rate).map_err(|index| PolicyError::NonFiniteAction { index })?;
        self.config
            .action_norm
            .normalize_rate(rate, &mut self.prev_rate);
        self.prev_action = Some(normalized);
        Ok(())
    }

    /// Records that `action` (raw units) was commanded one control period after the previous
    /// one: the rate becomes `(a_t - a_{t-1}) / control_dt` in normalized units (0 if no action
    /// was known).
    pub fn record_action(&mut self, action: &[f32]) -> Result<(), PolicyError> {
        let normalized = self.normalized_action(action)?;
        let dt = self.config.sampler.control_dt;
        match &self.prev_action {
            Some(previous) => {
                for ((rate, now), before) in
                    self.prev_rate.iter_mut().zip(&normalized).zip(previous)
                {
                    *rate = (now - before) / dt;
                }
            }
            None => self.prev_rate = [0.0; K],
        }
        self.prev_action = Some(normalized);
        Ok(())
    }

    /// Samples a new chunk from the current history and last commanded action, with noise from
    /// `noise`. Returns it in robot units (positions, velocities per second; the first `n k`
    /// values, step-major) and makes it the chunk [`Self::next_action`] reads from.
    pub fn act(&mut self, noise: Noise<'_>) -> Result<&Trajectory<N, K>, PolicyError> {
        let prev_action = self.prev_action.ok_or(PolicyError::NoPreviousAction)?;
        if !self.history.is_filled() {
            return Err(PolicyError::NoObservation);
        }
        self.chunk_ready = false;
        let dims = self.dims;
        let (m, o, k) = (dims.history, dims.obs_dim, dims.action_dim);
        let history_len = dims.history_len().ok_or(PolicyError::Capacity)?;
        let trajectory = dims.trajectory_len().ok_or(PolicyError::Capacity)?;
        let ordered = self
            .history_ordered
            .as_flattened_mut()
            .get_mut(..history_len)
            .ok_or(PolicyError::Capacity)?;
        for (slot, obs) in ordered
            .chunks_exact_mut(o.max(1))
            .zip(self.history.iter_oldest_first())
            .take(m)
        {
            slot.copy_from_slice(obs);
        }
        let conditioning = Conditioning {
            obs_history: ordered,
            prev_action: prev_action.get(..k).ok_or(PolicyError::Capacity)?,
            prev_rate: self.prev_rate.get(..k).ok_or(PolicyError::Capacity)?,
        };
        let input = self.network.input_width();
        let (positions, velocities) = self
            .normalized
            .values_mut(trajectory)
            .ok_or(PolicyError::Capacity)?;
        self.config.sampler.sample::<N, K, P, Net>(
            &dims,
            &mut self.network,
            &conditioning,
            noise,
            self.work.buffers(&dims, input)?,
            positions,
            velocities,
        )?;
        let norm = &self.config.action_norm;
        let (out_positions, out_velocities) = self
            .chunk
            .values_mut(trajectory)
            .ok_or(PolicyError::Capacity)?;
        norm.denormalize_trajectory::<N, K>(
            (positions, velocities),
            (out_positions, out_velocities),
        );
        self.chunk_ready = true;
        self.cursor = 0;
        Ok(&self.chunk)
    }

    /// The next action of the current chunk (raw units, `k` values; the rest of the array is
    /// zero), recorded as commanded ([`Self::record_action`]); `None` when no chunk is ready or
    /// all `n` were emitted.
    pub fn next_action(&mut self) -> Option<[f32; K]> {
        if !self.chunk_ready || self.cursor >= self.dims.horizon {
            return None;
        }
        let k = self.dims.action_dim;
        let start = self.cursor.checked_mul(k)?;
        let values = self
            .chunk
            .positions
            .as_flattened()
            .get(start..start.checked_add(k)?)?;
        let mut action = [0.0; K];
        action.get_mut(..k)?.copy_from_slice(values);
        self.record_action(action.get(..k)?).ok()?;
        self.cursor += 1;
        Some(action)
    }

    /// The current chunk in robot units, if one was sampled since the last reset.
    pub fn chunk(&self) -> Option<&Trajectory<N, K>> {
        self.chunk_ready.then_some(&self.chunk)
    }

    /// The last sampled chunk in normalized units (for comparison with float models).
    pub fn normalized_chunk(&self) -> &Trajectory<N, K> {
        &self.normalized
    }

    /// The last commanded action (normalized) and its rate (normalized units per second).
    pub fn previous_action_normalized(&self) -> Option<([f32; K], [f32; K])> {
        self.prev_action.map(|action| (action, self.prev_rate))
    }

    /// The observation history, oldest first (normalized).
    pub fn history(&self) -> &ObsHistory<M, O> {
        &self.history
    }

    /// The network (e.g. to read the last accumulators).
    pub fn network(&self) -> &Net {
        &self.network
    }

    /// The ProDMP parameters of the last network evaluation (DoF-major; the first `k p` values).
    pub fn last_params(&self) -> &[[f32; P]; K] {
        self.work.params()
    }

    /// The baked configuration.
    pub fn config(&self) -> &PolicyConfig<'a> {
        &self.config
    }
}
