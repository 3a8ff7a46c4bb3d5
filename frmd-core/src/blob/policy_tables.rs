//! The sections every policy blob carries besides its network: normalization, ProDMP decoder
//! tables and the step table; their emit and parse sides.
//!
//! Element types: normalization and ProDMP tables f32 (`[min; o]` then `[max; o]`; the six decoder
//! tables back to back as in [`ProDmpTables::split`]); steps `STEP_WORDS` u32 words each.

use super::container::{Data, Section, SectionWriter};
use super::{BlobError, Dimension, SectionId};
use crate::policy::{
    InputLayout, PolicyConfig, PolicyDims, ProDmpTables, RangeNormalizer, Sampler, StepConstants,
    StepTable, MAX_STEPS,
};
use serde::{Deserialize, Serialize};

/// Words per step in the step-constants section: `sigma, renoise_std, c_in, c_skip, c_out` as
/// f32 bit patterns, then `noise_variant`.
pub const STEP_WORDS: usize = 6;

/// The sections every policy blob carries (for [`SectionId::Policy`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PolicySection {
    /// Observation min/max.
    ObsNorm,
    /// Action min/max.
    ActionNorm,
    /// ProDMP tables.
    ProDmp,
    /// Step constants.
    Steps,
}

/// The sizes, control period and input layout every policy blob's descriptor starts with.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyHeader {
    /// Observation history length `m`.
    pub history: u32,
    /// Observation dimension `o`.
    pub obs_dim: u32,
    /// Action dimension `k`.
    pub action_dim: u32,
    /// Horizon `n`.
    pub horizon: u32,
    /// ProDMP parameters per DoF `p`.
    pub params_per_dof: u32,
    /// Control period, seconds.
    pub control_dt: f32,
    /// Model input layout.
    pub layout: InputLayout,
}

impl PolicyHeader {
    /// The header of `config` (every size must fit a `u32`).
    pub(crate) fn of(config: &PolicyConfig<'_>) -> Result<Self, BlobError> {
        let small = |value: usize| u32::try_from(value).map_err(|_| BlobError::TooLarge);
        let dims = config.dims();
        Ok(Self {
            history: small(dims.history)?,
            obs_dim: small(dims.obs_dim)?,
            action_dim: small(dims.action_dim)?,
            horizon: small(dims.horizon)?,
            params_per_dof: small(dims.params_per_dof)?,
            control_dt: config.sampler.control_dt,
            layout: config.sampler.layout,
        })
    }
}

/// The sections every policy blob's descriptor names (after its format's own fields).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicySections {
    /// f32 `[min; o]` then `[max; o]`.
    pub obs_norm: Section,
    /// f32 `[min; k]` then `[max; k]`.
    pub action_norm: Section,
    /// f32 `pos_params [n][p]`, `vel_params [n][p]`, `pos_y0 [n]`, `pos_v0 [n]`, `vel_y0 [n]`,
    /// `vel_v0 [n]`.
    pub prodmp: Section,
    /// u32 `[steps][STEP_WORDS]`.
    pub steps: Section,
}

fn step_words(step: &StepConstants) -> [u32; STEP_WORDS] {
    [
        step.sigma.to_bits(),
        step.renoise_std.to_bits(),
        step.c_in.to_bits(),
        step.c_skip.to_bits(),
        step.c_out.to_bits(),
        step.noise_variant,
    ]
}

fn same_len(a: &[f32], b: &[f32], id: SectionId) -> Result<(), BlobError> {
    if a.len() == b.len() {
        Ok(())
    } else {
        Err(BlobError::SectionLength(id))
    }
}

/// Lays out the policy sections of `config` (lengths checked against each other).
pub(crate) fn write(
    writer: &mut SectionWriter<'_>,
    config: &PolicyConfig<'_>,
) -> Result<PolicySections, BlobError> {
    let (obs, action) = (&config.obs_norm, &config.action_norm);
    same_len(obs.min, obs.max, PolicySection::ObsNorm.into())?;
    same_len(action.min, action.max, PolicySection::ActionNorm.into())?;
    let t = &config.sampler.decoder;
    let (n, p) = (t.horizon(), t.params_per_dof());
    let consistent = Some(t.pos_params.len()) == n.checked_mul(p)
        && t.vel_params.len() == t.pos_params.len()
        && [t.pos_v0, t.vel_y0, t.vel_v0].iter().all(|c| c.len() == n);
    if !consistent {
        return Err(BlobError::SectionLength(PolicySection::ProDmp.into()));
    }
    let tables = t
        .pos_params
        .iter()
        .chain(t.vel_params)
        .chain(t.pos_y0)
        .chain(t.pos_v0)
        .chain(t.vel_y0)
        .chain(t.vel_v0);
    let steps = config.sampler.steps.as_slice();
    Ok(PolicySections {
        obs_norm: writer.f32s(obs.min.iter().chain(obs.max))?,
        action_norm: writer.f32s(action.min.iter().chain(action.max))?,
        prodmp: writer.f32s(tables)?,
        steps: writer.u32s(steps.iter().flat_map(step_words))?,
    })
}

/// The validated policy tables of a blob (normalization and decoder borrowed from it, the steps
/// copied).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PolicyTables<'a> {
    pub(crate) dims: PolicyDims,
    pub(crate) control_dt: f32,
    pub(crate) obs_norm: RangeNormalizer<'a>,
    pub(crate) action_norm: RangeNormalizer<'a>,
    pub(crate) decoder: ProDmpTables<'a>,
    pub(crate) steps: StepTable,
}

impl<'a> PolicyTables<'a> {
    /// The policy configuration with the blob's `layout`.
    pub(crate) fn config(&self, layout: InputLayout) -> PolicyConfig<'a> {
        PolicyConfig {
            history: self.dims.history,
            obs_norm: self.obs_norm,
            action_norm: self.action_norm,
            sampler: Sampler {
                steps: self.steps,
                decoder: self.decoder,
                layout,
                control_dt: self.control_dt,
            },
        }
    }

    /// [`BlobError::DimensionMismatch`] naming the first size that differs from `expected`.
    pub(crate) fn check_dims(&self, expected: &PolicyDims) -> Result<(), BlobError> {
        let (d, e) = (&self.dims, expected);
        let pairs = [
            (d.history, e.history, Dimension::History),
            (d.obs_dim, e.obs_dim, Dimension::ObsDim),
            (d.action_dim, e.action_dim, Dimension::ActionDim),
            (d.horizon, e.horizon, Dimension::Horizon),
            (d.params_per_dof, e.params_per_dof, Dimension::ParamsPerDof),
        ];
        match pairs.iter().find(|(found, wanted, _)| found != wanted) {
            Some((_, _, which)) => Err(BlobError::DimensionMismatch(*which)),
            None => Ok(()),
        }
    }
}

/// Validates the sizes and control period of `header`, then the normalization ranges, ProDMP
/// tables and steps of `sections` (in that order, so the first failing check names the error).
pub(crate) fn read<'a>(
    data: &Data<'a>,
    header: &PolicyHeader,
    sections: &PolicySections,
) -> Result<PolicyTables<'a>, BlobError> {
    let h = header;
    let sizes = [
        h.history,
        h.obs_dim,
        h.action_dim,
        h.horizon,
        h.params_per_dof,
    ];
    let which = [
        Dimension::History,
        Dimension::ObsDim,
        Dimension::ActionDim,
        Dimension::Horizon,
        Dimension::ParamsPerDof,
    ];
    if let Some((_, zero)) = sizes.iter().zip(which).find(|(size, _)| **size == 0) {
        return Err(BlobError::ZeroDimension(zero));
    }
    let [history, obs_dim, action_dim, horizon, params_per_dof] = sizes.map(|d| d as usize);
    let dims = PolicyDims {
        history,
        obs_dim,
        action_dim,
        horizon,
        params_per_dof,
    };
    if !(h.control_dt.is_finite() && h.control_dt > 0.0) {
        return Err(BlobError::ControlPeriod);
    }
    let s = sections;
    let normalizer = |section, dim: usize, id| -> Result<RangeNormalizer<'a>, BlobError> {
        let values = data.finite(section, dim.checked_mul(2), id)?;
        let (min, max) = values
            .split_at_checked(dim)
            .ok_or(BlobError::SectionLength(id))?;
        Ok(RangeNormalizer::new(min, max))
    };
    let obs_norm = normalizer(s.obs_norm, obs_dim, PolicySection::ObsNorm.into())?;
    let action_norm = normalizer(s.action_norm, action_dim, PolicySection::ActionNorm.into())?;
    if obs_norm.validate().is_err() || action_norm.validate().is_err() {
        return Err(BlobError::Normalization);
    }
    let count = ProDmpTables::len_for(horizon, params_per_dof);
    let values = data.finite(s.prodmp, count, PolicySection::ProDmp.into())?;
    let decoder = ProDmpTables::split(values, horizon, params_per_dof)
        .ok_or(BlobError::SectionLength(PolicySection::ProDmp.into()))?;
    let steps = read_steps(data, s.steps)?;
    Ok(PolicyTables {
        dims,
        control_dt: h.control_dt,
        obs_norm,
        action_norm,
        decoder,
        steps,
    })
}

fn read_steps(data: &Data<'_>, section: Section) -> Result<StepTable, BlobError> {
    let words = data.cast::<u32>(section, PolicySection::Steps.into())?;
    if !words.len().is_multiple_of(STEP_WORDS) {
        return Err(BlobError::SectionLength(PolicySection::Steps.into()));
    }
    let count = words.len() / STEP_WORDS;
    if count == 0 || count > MAX_STEPS {
        return Err(BlobError::Steps);
    }
    let mut steps = [StepConstants::ZERO; MAX_STEPS];
    for (step, chunk) in steps.iter_mut().zip(words.chunks_exact(STEP_WORDS)) {
        if let [sigma, renoise, c_in, c_skip, c_out, index] = chunk {
            *step = StepConstants {
                sigma: f32::from_bits(*sigma),
                renoise_std: f32::from_bits(*renoise),
                c_in: f32::from_bits(*c_in),
                c_skip: f32::from_bits(*c_skip),
                c_out: f32::from_bits(*c_out),
                noise_variant: *index,
            };
        }
    }
    let table = StepTable::new(steps.get(..count).unwrap_or(&[]));
    table.validate().map_err(|_| BlobError::Steps)?;
    Ok(table)
}

/// Checks that every step selects one of `variants` noise-level variants (at least 1).
pub(crate) fn check_variants(steps: &StepTable, variants: usize) -> Result<(), BlobError> {
    let variants = variants.max(1);
    if steps
        .as_slice()
        .iter()
        .any(|s| s.noise_variant as usize >= variants)
    {
        return Err(BlobError::Steps);
    }
    Ok(())
}
