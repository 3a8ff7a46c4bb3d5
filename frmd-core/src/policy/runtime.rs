//! [`Policy`]: observation history, last commanded action, sampling and un-normalization.

use super::history::ObsHistory;
use super::network::Network;
use super::normalize::RangeNormalizer;
use super::sampler::{Conditioning, Noise, Sampler, SamplerWork, Trajectory};
use super::PolicyError;

/// Everything baked besides the network.
#[derive(Clone, Copy, Debug)]
pub struct PolicyConfig<'a, const O: usize, const K: usize, const N: usize, const P: usize> {
    /// Observation normalization (raw units).
    pub obs_norm: RangeNormalizer<O>,
    /// Action normalization (raw units).
    pub action_norm: RangeNormalizer<K>,
    /// Step table, decoder, input layout, control period.
    pub sampler: Sampler<'a, N, P>,
}

/// A policy over network `Net`; see the [module docs](super) for the call sequence and generics.
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
    config: PolicyConfig<'a, O, K, N, P>,
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
    /// Validates `config` against `network` (normalization, steps, layout widths, output width,
    /// bias variants) and builds the policy. Call [`Self::reset`] before the first chunk.
    pub fn new(config: PolicyConfig<'a, O, K, N, P>, network: Net) -> Result<Self, PolicyError> {
        config.obs_norm.validate()?;
        config.action_norm.validate()?;
        config.sampler.validate::<Net, M, O, K, I>(&network)?;
        Ok(Self {
            config,
            network,
            history: ObsHistory::new(),
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

    /// Starts an episode: forgets the observation history and the current chunk, and sets the
    /// last commanded action to `initial_action` (raw units, e.g. the robot's current position)
    /// with rate 0.
    pub fn reset(&mut self, initial_action: &[f32; K]) -> Result<(), PolicyError> {
        check_finite(initial_action).map_err(|index| PolicyError::NonFiniteAction { index })?;
        let mut normalized = [0.0; K];
        self.config
            .action_norm
            .normalize(initial_action, &mut normalized);
        self.prev_action = Some(normalized);
        self.prev_rate = [0.0; K];
        self.history.clear();
        self.chunk_ready = false;
        self.cursor = 0;
        Ok(())
    }

    /// Pushes the newest observation (raw units). NaN or infinite elements are rejected and the
    /// history is left unchanged.
    pub fn observe(&mut self, observation: &[f32; O]) -> Result<(), PolicyError> {
        check_finite(observation).map_err(|index| PolicyError::NonFiniteObservation { index })?;
        let mut normalized = [0.0; O];
        self.config.obs_norm.normalize(observation, &mut normalized);
        self.history.push(&normalized);
        Ok(())
    }

    /// Sets the last commanded action (raw units) and its rate (raw units per second), e.g. when
    /// the controller commands actions the policy did not emit.
    pub fn set_previous_action(
        &mut self,
        action: &[f32; K],
        rate: &[f32; K],
    ) -> Result<(), PolicyError> {
        check_finite(action).map_err(|index| PolicyError::NonFiniteAction { index })?;
        check_finite(rate).map_err(|index| PolicyError::NonFiniteAction { index })?;
        let mut normalized = [0.0; K];
        self.config.action_norm.normalize(action, &mut normalized);
        self.config
            .action_norm
            .normalize_rate(rate, &mut self.prev_rate);
        self.prev_action = Some(normalized);
        Ok(())
    }

    /// Records that `action` (raw units) was commanded one control period after the previous
    /// one: the rate becomes `(a_t - a_{t-1}) / control_dt` in normalized units (0 if no action
    /// was known).
    pub fn record_action(&mut self, action: &[f32; K]) -> Result<(), PolicyError> {
        check_finite(action).map_err(|index| PolicyError::NonFiniteAction { index })?;
        let mut normalized = [0.0; K];
        self.config.action_norm.normalize(action, &mut normalized);
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
    /// `noise`. Returns it in robot units (positions, velocities per second) and makes it the
    /// chunk [`Self::next_action`] reads from.
    pub fn act(&mut self, noise: Noise<'_>) -> Result<&Trajectory<N, K>, PolicyError> {
        let prev_action = self.prev_action.ok_or(PolicyError::NoPreviousAction)?;
        if !self.history.is_filled() {
            return Err(PolicyError::NoObservation);
        }
        self.chunk_ready = false;
        for (slot, obs) in self
            .history_ordered
            .iter_mut()
            .zip(self.history.iter_oldest_first())
        {
            *slot = *obs;
        }
        let conditioning = Conditioning {
            obs_history: &self.history_ordered,
            prev_action: &prev_action,
            prev_rate: &self.prev_rate,
        };
        self.config.sampler.sample(
            &mut self.network,
            &conditioning,
            noise,
            &mut self.work,
            &mut self.normalized,
        )?;
        let norm = &self.config.action_norm;
        let rows = self
            .normalized
            .positions
            .iter()
            .zip(&self.normalized.velocities)
            .zip(
                self.chunk
                    .positions
                    .iter_mut()
                    .zip(self.chunk.velocities.iter_mut()),
            );
        for ((pos, vel), (pos_out, vel_out)) in rows {
            norm.denormalize(pos, pos_out);
            norm.denormalize_rate(vel, vel_out);
        }
        self.chunk_ready = true;
        self.cursor = 0;
        Ok(&self.chunk)
    }

    /// The next action of the current chunk (raw units), recorded as commanded
    /// ([`Self::record_action`]); `None` when no chunk is ready or all `N` were emitted.
    pub fn next_action(&mut self) -> Option<[f32; K]> {
        if !self.chunk_ready {
            return None;
        }
        let action = *self.chunk.positions.get(self.cursor)?;
        self.record_action(&action).ok()?;
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

    /// The ProDMP parameters of the last network evaluation.
    pub fn last_params(&self) -> &[[f32; P]; K] {
        self.work.params()
    }

    /// The baked configuration.
    pub fn config(&self) -> &PolicyConfig<'a, O, K, N, P> {
        &self.config
    }
}
