//! Consistency sampler (DESIGN.md s.3) for the baked student, one step or a few (2..=4).
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

use crate::prodmp::BakedProDmp;
use crate::rng::Rng;

use super::layout::{InputLayout, InputSources};
use super::network::Network;
use super::PolicyError;

/// Most sampling steps a table may hold.
pub const MAX_STEPS: usize = 4;

/// Constants of one sampling step, folded by the exporter from the sigma schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepConstants {
    /// Noise level of this step (normalized action units).
    pub sigma: f32,
    /// Standard deviation of the fresh noise added to the previous output:
    /// `sqrt(sigma^2 - sigma_min^2)`; 0 for the first step (which starts from `sigma * z`).
    pub renoise_std: f32,
    /// Input scale `c_in(sigma) = 1 / sqrt(sigma^2 + sigma_data^2)`.
    pub c_in: f32,
    /// Skip scale `c_skip(sigma)`.
    pub c_skip: f32,
    /// Output scale `c_out(sigma)`.
    pub c_out: f32,
    /// Which first-layer bias variant (noise embedding at `sigma` folded in) this step uses.
    pub first_layer_bias_index: u32,
}

impl StepConstants {
    /// Checks one step: all values finite, `sigma > 0`, `c_in > 0`, `renoise_std >= 0`, and
    /// `renoise_std == 0` for the first step.
    pub fn validate(&self, first: bool) -> Result<(), PolicyError> {
        let values = [
            self.sigma,
            self.renoise_std,
            self.c_in,
            self.c_skip,
            self.c_out,
        ];
        let finite = values.iter().all(|v| v.is_finite());
        if !finite
            || self.sigma <= 0.0
            || self.c_in <= 0.0
            || self.renoise_std < 0.0
            || (first && self.renoise_std != 0.0)
        {
            return Err(PolicyError::InvalidStepConstants);
        }
        Ok(())
    }
}

/// Checks a whole table: `1..=MAX_STEPS` steps, each valid.
pub fn validate_steps(steps: &[StepConstants]) -> Result<(), PolicyError> {
    if steps.is_empty() || steps.len() > MAX_STEPS {
        return Err(PolicyError::StepCount);
    }
    steps
        .iter()
        .enumerate()
        .try_for_each(|(i, step)| step.validate(i == 0))
}

/// Where the Gaussian noise comes from.
#[derive(Debug)]
pub enum Noise<'n> {
    /// Drawn from a seeded generator, `N * K` values per step in step-major order.
    Rng(&'n mut Rng),
    /// Supplied by the caller: `steps * N * K` values, step after step, each step-major.
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

/// Positions and velocities of a trajectory, `[t][d]` for the query times `dt .. N dt`.
#[derive(Clone, Copy, Debug, PartialEq)]
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
}

impl<const N: usize, const K: usize> Default for Trajectory<N, K> {
    fn default() -> Self {
        Self::zeros()
    }
}

/// Conditioning of one chunk, normalized units.
#[derive(Clone, Copy, Debug)]
pub struct Conditioning<'c, const M: usize, const O: usize, const K: usize> {
    /// Observation history, oldest first.
    pub obs_history: &'c [[f32; O]; M],
    /// Last commanded action (ProDMP `y0`).
    pub prev_action: &'c [f32; K],
    /// Its rate, normalized units per second (ProDMP `v0`).
    pub prev_rate: &'c [f32; K],
}

/// Working memory of [`Sampler::sample`]; `I` must be at least the network input width.
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

    /// The ProDMP parameters of the last network evaluation (`params[d] = [w.., g]`).
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

/// Everything the sampler needs besides the network: step table, decoder, input layout and the
/// control period (s) between query times.
#[derive(Clone, Copy, Debug)]
pub struct Sampler<'s, const N: usize, const P: usize> {
    /// Per-step constants, `1..=MAX_STEPS` entries.
    pub steps: &'s [StepConstants],
    /// Baked ProDMP decoder (query times `dt .. N dt`).
    pub decoder: &'s BakedProDmp<N, P>,
    /// Model input layout.
    pub layout: InputLayout,
    /// Control period in seconds (the decoder's `tau / N`).
    pub control_dt: f32,
}

impl<const N: usize, const P: usize> Sampler<'_, N, P> {
    /// Checks the step table, the layout, the control period, and that `net` takes the layout's
    /// width (at most `I`), outputs `K * P` values and has every bias variant the steps use.
    pub fn validate<
        Net: Network,
        const M: usize,
        const O: usize,
        const K: usize,
        const I: usize,
    >(
        &self,
        net: &Net,
    ) -> Result<(), PolicyError> {
        validate_steps(self.steps)?;
        self.layout.validate()?;
        if !(self.control_dt.is_finite() && self.control_dt > 0.0) {
            return Err(PolicyError::InvalidControlPeriod);
        }
        let width = self
            .layout
            .width(M, O, K, N)
            .ok_or(PolicyError::InputWidth)?;
        if width != net.input_width() || width > I {
            return Err(PolicyError::InputWidth);
        }
        if Some(net.output_width()) != K.checked_mul(P) {
            return Err(PolicyError::OutputWidth);
        }
        let variants = net.num_first_layer_biases().max(1);
        if self
            .steps
            .iter()
            .any(|s| s.first_layer_bias_index as usize >= variants)
        {
            return Err(PolicyError::FirstLayerBiasIndex);
        }
        Ok(())
    }

    /// Runs all steps and writes the chunk (normalized units) into `out`.
    pub fn sample<Net: Network, const M: usize, const O: usize, const K: usize, const I: usize>(
        &self,
        net: &mut Net,
        conditioning: &Conditioning<'_, M, O, K>,
        mut noise: Noise<'_>,
        work: &mut SamplerWork<K, N, P, I>,
        out: &mut Trajectory<N, K>,
    ) -> Result<(), PolicyError> {
        self.validate::<Net, M, O, K, I>(net)?;
        let width = net.input_width();
        for (index, step) in self.steps.iter().enumerate() {
            noise.fill(index, work.noise.as_flattened_mut())?;
            let fresh = work
                .noisy
                .iter_mut()
                .flatten()
                .zip(work.noise.iter().flatten());
            if index == 0 {
                for (x, z) in fresh {
                    *x = step.sigma * z;
                }
            } else {
                let previous = out.positions.iter().flatten();
                for ((x, z), f) in fresh.zip(previous) {
                    *x = f + step.renoise_std * z;
                }
            }
            let sources = InputSources {
                obs_history: conditioning.obs_history,
                prev_action: conditioning.prev_action,
                prev_rate: conditioning.prev_rate,
                noisy: &work.noisy,
                c_in: step.c_in,
            };
            let input = work.input.get_mut(..width).ok_or(PolicyError::InputWidth)?;
            self.layout.write(&sources, input)?;
            net.forward(
                step.first_layer_bias_index as usize,
                input,
                work.params.as_flattened_mut(),
            )?;
            decode(
                self.decoder,
                &work.params,
                conditioning.prev_action,
                conditioning.prev_rate,
                &mut work.decoded,
            )?;
            self.combine(
                step,
                &work.noisy,
                (conditioning.prev_action, conditioning.prev_rate),
                &work.decoded,
                out,
            );
        }
        let finite = out
            .positions
            .iter()
            .chain(out.velocities.iter())
            .flatten()
            .all(|v| v.is_finite());
        if finite {
            Ok(())
        } else {
            Err(PolicyError::NonFiniteOutput)
        }
    }

    /// `f = b + c_skip (x - b) + c_out (decoded - b)` for positions; velocities as in the module
    /// docs.
    fn combine<const K: usize>(
        &self,
        step: &StepConstants,
        noisy: &[[f32; K]; N],
        conditioning: (&[f32; K], &[f32; K]),
        decoded: &Trajectory<N, K>,
        out: &mut Trajectory<N, K>,
    ) {
        let (prev_action, prev_rate) = conditioning;
        let mut before = prev_action;
        let boundary = self.decoder.boundary_rows();
        let rows = noisy
            .iter()
            .zip(decoded.positions.iter().zip(decoded.velocities.iter()))
            .zip(out.positions.iter_mut().zip(out.velocities.iter_mut()))
            .zip(boundary);
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

/// The one place the policy calls the ProDMP decoder: DoF-major parameters, `y0`, `v0`
/// (normalized units, units/s) to normalized positions and velocities.
fn decode<const N: usize, const P: usize, const K: usize>(
    decoder: &BakedProDmp<N, P>,
    params: &[[f32; P]; K],
    y0: &[f32; K],
    v0: &[f32; K],
    out: &mut Trajectory<N, K>,
) -> Result<(), PolicyError> {
    decoder
        .decode(params, y0, v0, &mut out.positions, &mut out.velocities)
        .map_err(PolicyError::Decode)
}
