//! The model input vector: which conditioning segments appear, in which order.
//!
//! The float models and the firmware must agree on the input order; the exporter describes it
//! with an [`InputLayout`] (baked as a `const` or stored in the blob descriptor), so the firmware
//! never hard-codes it. Segments and their lengths (normalized units throughout):
//!
//! | segment | length | values |
//! | --- | --- | --- |
//! | [`InputSegment::ObsHistory`] | `m o` | observations oldest first, each `o` values |
//! | [`InputSegment::PrevAction`] | `k` | last commanded action (ProDMP `y0`) |
//! | [`InputSegment::PrevRate`] | `k` | its rate (per second, ProDMP `v0`) times [`InputLayout::rate_scale`] |
//! | [`InputSegment::NoisyTrajectory`] | `n k` | `c_in * x_noisy`, step-major (`x[t][d]`) |
//!
//! The noise-level embedding is not an input: the exporter folds it into the network (one
//! variant per sampling step, see [`super::StepConstants::noise_variant`]).

use serde::{Deserialize, Serialize};

use super::{PolicyDims, PolicyError};

/// Most segments an [`InputLayout`] can list.
pub const MAX_INPUT_SEGMENTS: usize = 4;

/// One contiguous part of the model input.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum InputSegment {
    /// `M` normalized observations, oldest first (`M * O` values).
    ObsHistory,
    /// Last commanded action, normalized (`K` values).
    PrevAction,
    /// Its finite-difference rate in normalized units per second, times `rate_scale` (`K`).
    PrevRate,
    /// The noisy trajectory scaled by the step's `c_in`, step-major (`N * K` values).
    NoisyTrajectory,
}

impl InputSegment {
    /// Number of input values of this segment for history `m`, observation dim `o`, action dim `k`,
    /// horizon `n`; `None` on overflow.
    pub fn len(self, m: usize, o: usize, k: usize, n: usize) -> Option<usize> {
        match self {
            Self::ObsHistory => m.checked_mul(o),
            Self::PrevAction | Self::PrevRate => Some(k),
            Self::NoisyTrajectory => n.checked_mul(k),
        }
    }
}

/// Ordered list of input segments (each at most once) plus the rate input scale.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputLayout {
    /// Segments in input order; only the first `count` entries are used.
    segments: [InputSegment; MAX_INPUT_SEGMENTS],
    count: u8,
    /// Factor applied to the normalized rate before it enters the input (for example the control
    /// period when the float model is conditioned on `v0 * dt`, 1 for the plain rate).
    pub rate_scale: f32,
}

/// The four conditioning values the input is built from, all normalized.
#[derive(Clone, Copy, Debug)]
pub struct InputSources<'s> {
    /// Observation history, oldest first (`m o` values).
    pub obs_history: &'s [f32],
    /// Last commanded action (`k`).
    pub prev_action: &'s [f32],
    /// Its rate in normalized units per second (`k`).
    pub prev_rate: &'s [f32],
    /// Unscaled noisy trajectory `x[t][d]` (`n k`, step-major).
    pub noisy: &'s [f32],
    /// The step's input scale `c_in`.
    pub c_in: f32,
}

impl InputLayout {
    /// Layout from `segments` in order; at most [`MAX_INPUT_SEGMENTS`], each at most once, and
    /// `NoisyTrajectory` is required; `rate_scale` must be finite.
    pub fn new(segments: &[InputSegment], rate_scale: f32) -> Result<Self, PolicyError> {
        let mut layout = Self {
            segments: [InputSegment::NoisyTrajectory; MAX_INPUT_SEGMENTS],
            count: 0,
            rate_scale,
        };
        if segments.len() > MAX_INPUT_SEGMENTS {
            return Err(PolicyError::InvalidLayout);
        }
        for (slot, segment) in layout.segments.iter_mut().zip(segments) {
            *slot = *segment;
        }
        layout.count = segments.len() as u8;
        layout.validate()?;
        Ok(layout)
    }

    /// Unchecked `const` constructor for generated code: the first `count` of `segments` are used.
    /// [`Self::validate`] (run by [`super::Policy::new`]) checks it.
    pub const fn from_segments(
        segments: [InputSegment; MAX_INPUT_SEGMENTS],
        count: u8,
        rate_scale: f32,
    ) -> Self {
        Self {
            segments,
            count,
            rate_scale,
        }
    }

    /// The conventional order `[ObsHistory, PrevAction, PrevRate, NoisyTrajectory]`.
    pub const fn standard(rate_scale: f32) -> Self {
        Self {
            segments: [
                InputSegment::ObsHistory,
                InputSegment::PrevAction,
                InputSegment::PrevRate,
                InputSegment::NoisyTrajectory,
            ],
            count: 4,
            rate_scale,
        }
    }

    /// The segments in input order.
    pub fn segments(&self) -> &[InputSegment] {
        self.segments.get(..usize::from(self.count)).unwrap_or(&[])
    }

    /// Checks: count within capacity, no segment twice, the noisy trajectory present, finite
    /// `rate_scale`.
    pub fn validate(&self) -> Result<(), PolicyError> {
        let count = usize::from(self.count);
        let segments = self
            .segments
            .get(..count)
            .ok_or(PolicyError::InvalidLayout)?;
        let repeated = segments
            .iter()
            .enumerate()
            .any(|(i, s)| segments.iter().skip(i + 1).any(|t| t == s));
        let has_trajectory = segments.contains(&InputSegment::NoisyTrajectory);
        if repeated || !has_trajectory || !self.rate_scale.is_finite() {
            return Err(PolicyError::InvalidLayout);
        }
        Ok(())
    }

    /// Total input width for the given sizes; `None` on overflow.
    pub fn width(&self, m: usize, o: usize, k: usize, n: usize) -> Option<usize> {
        self.segments()
            .iter()
            .try_fold(0_usize, |acc, s| acc.checked_add(s.len(m, o, k, n)?))
    }

    /// [`Self::width`] of `dims`.
    pub fn width_of(&self, dims: &PolicyDims) -> Option<usize> {
        self.width(dims.history, dims.obs_dim, dims.action_dim, dims.horizon)
    }

    /// Writes the input vector into `out`, which must be exactly [`Self::width_of`] `dims` long;
    /// every source must hold its segment's length.
    pub fn write(
        &self,
        dims: &PolicyDims,
        sources: &InputSources<'_>,
        out: &mut [f32],
    ) -> Result<(), PolicyError> {
        if self.width_of(dims) != Some(out.len()) {
            return Err(PolicyError::InputWidth);
        }
        let (m, o, k, n) = (dims.history, dims.obs_dim, dims.action_dim, dims.horizon);
        let mut rest = out;
        for segment in self.segments() {
            let len = segment.len(m, o, k, n).ok_or(PolicyError::InputWidth)?;
            let (head, tail) = core::mem::take(&mut rest)
                .split_at_mut_checked(len)
                .ok_or(PolicyError::InputWidth)?;
            let source = match segment {
                InputSegment::ObsHistory => sources.obs_history,
                InputSegment::PrevAction => sources.prev_action,
                InputSegment::PrevRate => sources.prev_rate,
                InputSegment::NoisyTrajectory => sources.noisy,
            };
            if source.len() != len {
                return Err(PolicyError::InputWidth);
            }
            match segment {
                InputSegment::ObsHistory | InputSegment::PrevAction => copy(head, source),
                InputSegment::PrevRate => {
                    for (o, r) in head.iter_mut().zip(source) {
                        *o = r * self.rate_scale;
                    }
                }
                InputSegment::NoisyTrajectory => {
                    for (o, x) in head.iter_mut().zip(source) {
                        *o = sources.c_in * x;
                    }
                }
            }
            rest = tail;
        }
        Ok(())
    }
}

/// Element-wise copy of the common prefix (lengths are equal by construction at every call).
fn copy(dst: &mut [f32], src: &[f32]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}
