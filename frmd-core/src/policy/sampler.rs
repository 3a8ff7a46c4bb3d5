//! Consistency sampler (docs/design.md s.3) for the baked student, one step or a few (2..=4).
//!
//! The exporter folds every sigma-dependent constant into a per-step [`StepConstants`] table, so
//! the firmware has no sigma schedule. With `x` the unscaled noisy trajectory (`N x K`,
//! step-major, normalized action units) and `z ~ N(0, 1)` of the same shape:
//! - step 0: `x = sigma_0 z` (`sigma_0 = sigma_max`);
//! - step i > 0: `x = f_{i-1} + renoise_std_i z` (`renoise_std_i = sqrt(sigma_i^2 - sigma_min^2)`);
//! - every step: `f_i = b + c_skip_i (x - b) + c_out_i (g - b)` with
//!   `g = decode(net(input(c_in_i x)), y0, v0)` and `b = decode(0, y0, v0)` the decoder's
//!   initial-condition part ([`skip_output`]): the skip acts on the free part of the chunk only,
//!   so every output starts from `y0`, `v0` (docs/design.md, "student parametrization").
//!   A direct-output student (the decoded trajectory is the output) has `c_skip = 0`, `c_out = 1`.
//!
//! The result `f` of the last step is the action chunk in normalized units. Its velocities are
//! the same combination of the decoded velocities, the initial-condition velocities and the
//! backward difference of `x` / control_dt (with `x` before the first query time taken as `y0`).

use crate::rng::Rng;

use super::decoder::ProDmpTables;
use super::dims::{all_finite, fixed_row_pairs, fixed_rows};
use super::layout::{InputLayout, InputSources};
use super::network::Network;
use super::steps::{StepConstants, StepTable};
use super::{PolicyDims, PolicyError};

/// Where the Gaussian noise comes from.
#[derive(Debug)]
pub enum Noise<'n> {
    /// Drawn from a seeded generator, `n k` values per step in step-major order.
    Rng(&'n mut Rng),
    /// Supplied by the caller: `steps n k` values, step after step, each step-major.
    Given(&'n [f32]),
}

impl Noise<'_> {
    fn fill(&mut self, step: usize, out: &mut [f32]) -> Result<(), PolicyError> {
        match self {
            Self::Rng(rng) => rng.fill_gaussian(out),
            Self::Given(values) => {
                let start = step
                    .checked_mul(out.len())
                    .ok_or(PolicyError::NoiseLength)?;
                let end = start
                    .checked_add(out.len())
                    .ok_or(PolicyError::NoiseLength)?;
                let chunk = values.get(start..end).ok_or(PolicyError::NoiseLength)?;
                if chunk.iter().any(|v| !v.is_finite()) {
                    return Err(PolicyError::NonFiniteNoise);
                }
                for (o, v) in out.iter_mut().zip(chunk) {
                    *o = *v;
                }
            }
        }
        Ok(())
    }
}

/// Positions and velocities of a trajectory for the query times `dt .. n dt`, with capacity for
/// `N` times of `K` DoFs: the `n k` values of a policy with smaller sizes are the first ones of
/// the flattened arrays, step-major (for `n = N`, `k = K` simply `[t][d]`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Trajectory<const N: usize, const K: usize> {
    /// Positions (normalized or robot units, as stated where used).
    pub positions: [[f32; K]; N],
    /// Velocities (the same units per second).
    pub velocities: [[f32; K]; N],
}

impl<const N: usize, const K: usize> Trajectory<N, K> {
    /// All zeros.
    pub const fn zeros() -> Self {
        Self {
            positions: [[0.0; K]; N],
            velocities: [[0.0; K]; N],
        }
    }

    /// The first `len` positions and velocities (flattened), or `None` beyond the capacity.
    pub fn values(&self, len: usize) -> Option<(&[f32], &[f32])> {
        let positions = self.positions.as_flattened().get(..len)?;
        Some((positions, self.velocities.as_flattened().get(..len)?))
    }

    /// [`Self::values`], mutable.
    pub fn values_mut(&mut self, len: usize) -> Option<(&mut [f32], &mut [f32])> {
        let positions = self.positions.as_flattened_mut().get_mut(..len)?;
        Some((
            positions,
            self.velocities.as_flattened_mut().get_mut(..len)?,
        ))
    }
}

impl<const N: usize, const K: usize> Default for Trajectory<N, K> {
    fn default() -> Self {
        Self::zeros()
    }
}

/// Conditioning of one chunk, normalized units.
#[derive(Clone, Copy, Debug)]
pub struct Conditioning<'c> {
    /// Observation history, oldest first (`m o` values).
    pub obs_history: &'c [f32],
    /// Last commanded action (ProDMP `y0`, `k` values).
    pub prev_action: &'c [f32],
    /// Its rate, normalized units per second (ProDMP `v0`, `k` values).
    pub prev_rate: &'c [f32],
}

/// Working memory of [`Sampler::sample`], borrowed: `noisy` and `noise` (`n k`), the network
/// `input` (its width), the ProDMP `params` (`k p`, DoF-major) and the decoded trajectory
/// (`n k` each).
#[derive(Debug)]
pub struct SamplerBuffers<'w> {
    /// The noisy trajectory `x` of the current step.
    pub noisy: &'w mut [f32],
    /// The step's standard-normal noise.
    pub noise: &'w mut [f32],
    /// The network input.
    pub input: &'w mut [f32],
    /// The network output.
    pub params: &'w mut [f32],
    /// Decoded positions.
    pub decoded_positions: &'w mut [f32],
    /// Decoded velocities.
    pub decoded_velocities: &'w mut [f32],
}

/// [`SamplerBuffers`] as fixed arrays with capacity for `K` DoFs, horizon `N`, `P` parameters per
/// DoF and an input of `I` values.
#[derive(Clone, Debug)]
pub struct SamplerWork<const K: usize, const N: usize, const P: usize, const I: usize> {
    noisy: [[f32; K]; N],
    noise: [[f32; K]; N],
    input: [f32; I],
    params: [[f32; P]; K],
    decoded: Trajectory<N, K>,
}

impl<const K: usize, const N: usize, const P: usize, const I: usize> SamplerWork<K, N, P, I> {
    /// Zeroed working memory.
    pub const fn new() -> Self {
        Self {
            noisy: [[0.0; K]; N],
            noise: [[0.0; K]; N],
            input: [0.0; I],
            params: [[0.0; P]; K],
            decoded: Trajectory::zeros(),
        }
    }

    /// The arrays cut to `dims` and an input of `input` values, or [`PolicyError::Capacity`].
    pub fn buffers(
        &mut self,
        dims: &PolicyDims,
        input: usize,
    ) -> Result<SamplerBuffers<'_>, PolicyError> {
        let trajectory = dims.trajectory_len().ok_or(PolicyError::Capacity)?;
        let params = dims.params_len().ok_or(PolicyError::Capacity)?;
        let (decoded_positions, decoded_velocities) = self
            .decoded
            .values_mut(trajectory)
            .ok_or(PolicyError::Capacity)?;
        Ok(SamplerBuffers {
            noisy: prefix(self.noisy.as_flattened_mut(), trajectory)?,
            noise: prefix(self.noise.as_flattened_mut(), trajectory)?,
            input: prefix(&mut self.input, input)?,
            params: prefix(self.params.as_flattened_mut(), params)?,
            decoded_positions,
            decoded_velocities,
        })
    }

    /// The ProDMP parameters of the last network evaluation, DoF-major (the first `k p`
    /// values; for `k = K`, `p = P` `params[d] = [w.., g]`).
    pub fn params(&self) -> &[[f32; P]; K] {
        &self.params
    }
}

impl<const K: usize, const N: usize, const P: usize, const I: usize> Default
    for SamplerWork<K, N, P, I>
{
    fn default() -> Self {
        Self::new()
    }
}

/// The first `len` values, or [`PolicyError::Capacity`].
fn prefix(values: &mut [f32], len: usize) -> Result<&mut [f32], PolicyError> {
    values.get_mut(..len).ok_or(PolicyError::Capacity)
}

/// Everything the sampler needs besides the network: step table, decoder, input layout and the
/// control period (s) between query times.
#[derive(Clone, Copy, Debug)]
pub struct Sampler<'s> {
    /// Per-step constants, `1..=MAX_STEPS` entries.
    pub steps: StepTable,
    /// Baked ProDMP decoder tables (query times `dt .. n dt`).
    pub decoder: ProDmpTables<'s>,
    /// Model input layout.
    pub layout: InputLayout,
    /// Control period in seconds (the decoder's `tau / n`).
    pub control_dt: f32,
}

impl Sampler<'_> {
    /// Checks the step table, the layout, the control period, that the decoder has `dims`'
    /// horizon and parameters, and that `net` takes the layout's width, outputs `k p` values and
    /// has every noise-level variant the steps use (the decoder tables' own consistency and
    /// values are [`ProDmpTables::validate`]'s, which [`super::Policy::new`] runs once).
    pub fn validate<Net: Network>(&self, dims: &PolicyDims, net: &Net) -> Result<(), PolicyError> {
        self.steps.validate()?;
        self.layout.validate()?;
        if !(self.control_dt.is_finite() && self.control_dt > 0.0) {
            return Err(PolicyError::InvalidControlPeriod);
        }
        if (self.decoder.horizon(), self.decoder.params_per_dof())
            != (dims.horizon, dims.params_per_dof)
        {
            return Err(PolicyError::Decode(crate::prodmp::ProDmpError::WrongLength));
        }
        let width = self.layout.width_of(dims).ok_or(PolicyError::InputWidth)?;
        if width != net.input_width() {
            return Err(PolicyError::InputWidth);
        }
        if Some(net.output_width()) != dims.params_len() {
            return Err(PolicyError::OutputWidth);
        }
        let variants = net.num_noise_variants().max(1);
        if self
            .steps
            .as_slice()
            .iter()
            .any(|s| s.noise_variant as usize >= variants)
        {
            return Err(PolicyError::NoiseVariantIndex);
        }
        Ok(())
    }

    /// Runs all steps and writes the chunk (normalized units, `n k` positions and velocities,
    /// step-major) into `positions` and `velocities`. `N`, `K` and `P` are the caller's
    /// capacities (see [`ProDmpTables::decode`]).
    #[allow(clippy::too_many_arguments)]
    pub fn sample<const N: usize, const K: usize, const P: usize, Net: Network>(
        &self,
        dims: &PolicyDims,
        net: &mut Net,
        conditioning: &Conditioning<'_>,
        mut noise: Noise<'_>,
        work: SamplerBuffers<'_>,
        positions: &mut [f32],
        velocities: &mut [f32],
    ) -> Result<(), PolicyError> {
        self.validate(dims, net)?;
        let k = dims.action_dim;
        if k == 0 {
            return Err(PolicyError::Capacity);
        }
        let trajectory = dims.trajectory_len().ok_or(PolicyError::Capacity)?;
        let width = net.input_width();
        let SamplerBuffers {
            noisy,
            noise: z,
            input,
            params,
            decoded_positions,
            decoded_velocities,
        } = work;
        let input = input.get_mut(..width).ok_or(PolicyError::InputWidth)?;
        if [noisy.len(), z.len(), positions.len(), velocities.len()] != [trajectory; 4] {
            return Err(PolicyError::Capacity);
        }
        for (index, step) in self.steps.as_slice().iter().enumerate() {
            noise.fill(index, z)?;
            let fresh = noisy.iter_mut().zip(z.iter());
            if index == 0 {
                for (x, z) in fresh {
                    *x = step.sigma * z;
                }
            } else {
                for ((x, z), f) in fresh.zip(positions.iter()) {
                    *x = f + step.renoise_std * z;
                }
            }
            let sources = InputSources {
                obs_history: conditioning.obs_history,
                prev_action: conditioning.prev_action,
                prev_rate: conditioning.prev_rate,
                noisy,
                c_in: step.c_in,
            };
            self.layout.write(dims, &sources, input)?;
            net.forward(step.noise_variant as usize, input, params)?;
            self.decoder
                .decode::<N, K, P>(
                    params,
                    conditioning.prev_action,
                    conditioning.prev_rate,
                    decoded_positions,
                    decoded_velocities,
                )
                .map_err(PolicyError::Decode)?;
            let decoded = (&*decoded_positions, &*decoded_velocities);
            let fixed = (
                fixed_rows::<N, K>(noisy),
                fixed_rows::<N, K>(decoded.0),
                fixed_rows::<N, K>(decoded.1),
            );
            if let (Some(noisy), Some(decoded_pos), Some(decoded_vel)) = fixed {
                if let Some(outputs) = fixed_row_pairs::<N, K>(positions, velocities) {
                    let decoded = decoded_pos.zip(decoded_vel);
                    self.combine(step, noisy, conditioning, decoded, outputs);
                }
            } else {
                let outputs = positions
                    .chunks_exact_mut(k)
                    .zip(velocities.chunks_exact_mut(k));
                let decoded = decoded.0.chunks_exact(k).zip(decoded.1.chunks_exact(k));
                self.combine(step, noisy.chunks_exact(k), conditioning, decoded, outputs);
            }
        }
        if all_finite(positions, velocities) {
            Ok(())
        } else {
            Err(PolicyError::NonFiniteOutput)
        }
    }

    /// `f = b + c_skip (x - b) + c_out (decoded - b)` for positions; velocities as in the module
    /// docs. Every trajectory comes as rows of `k` values, one per query time.
    #[inline(always)]
    fn combine<'r, 'o>(
        &self,
        step: &StepConstants,
        noisy: impl Iterator<Item = &'r [f32]>,
        conditioning: &Conditioning<'_>,
        decoded: impl Iterator<Item = (&'r [f32], &'r [f32])>,
        outputs: impl Iterator<Item = (&'o mut [f32], &'o mut [f32])>,
    ) {
        let (prev_action, prev_rate) = (conditioning.prev_action, conditioning.prev_rate);
        let mut before = prev_action;
        let rows = noisy
            .zip(decoded)
            .zip(outputs)
            .zip(self.decoder.boundary_rows());
        for (((x_t, (pos_t, vel_t)), (out_pos, out_vel)), b_t) in rows {
            let dofs = x_t
                .iter()
                .zip(before)
                .zip(pos_t.iter().zip(vel_t))
                .zip(out_pos.iter_mut().zip(out_vel.iter_mut()))
                .zip(prev_action.iter().zip(prev_rate));
            for ((((x, x_before), (p, v)), (o_p, o_v)), (y0, v0)) in dofs {
                let (b_pos, b_vel) = b_t.at(*y0, *v0);
                *o_p = skip_output(step.c_skip, step.c_out, *x, *p, b_pos);
                *o_v = skip_output(
                    step.c_skip,
                    step.c_out,
                    (x - x_before) / self.control_dt,
                    *v,
                    b_vel,
                );
            }
            before = x_t;
        }
    }
}

/// The consistency output of one value: `b + c_skip (x - b) + c_out (g - b)`, evaluated as
/// `c_skip x + c_out g + (1 - c_skip - c_out) b` in f32 (the one place this rounding is written;
/// the exporter's reference sampler calls it too). With `c_skip = 0`, `c_out = 1` it is `g`.
#[inline]
pub fn skip_output(c_skip: f32, c_out: f32, noisy: f32, decoded: f32, boundary: f32) -> f32 {
    let rest = 1.0 - c_skip - c_out;
    c_skip * noisy + c_out * decoded + rest * boundary
}
