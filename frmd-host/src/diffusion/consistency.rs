//! The pieces a consistency-distillation objective is made of: the distance between student and
//! target, the weight of a pair of levels, how the pair's levels are drawn (adjacent or far
//! apart, uniform or log-normal over the grid), and a curriculum on the number of levels N.
//!
//! The defaults are the paper's Algorithm 1 (squared error, weight 1, adjacent levels drawn
//! uniformly, fixed N). The alternatives are those of improved consistency training (Song &
//! Dhariwal 2023: pseudo-Huber distance, weight 1 / (sigma_high - sigma_low), log-normal level
//! index, N doubling during training) and consistency-trajectory-style long jumps (Kim et al.
//! 2023, as Consistency Policy uses them). docs/experiments.md, "Distillation objectives", has
//! what each measured.
use crate::rng::HostRng;
use anyhow::bail;
use candle_core::{Tensor, D};
use frmd_core::sigma::SigmaConfig;
use serde::{Deserialize, Serialize};

use super::precond::column;
use super::sigma_err;

/// Distance between the student's output and its target, per sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Distance {
    /// Mean squared error over the chunk (the paper's).
    L2,
    /// `sqrt(|a - b|^2 + c^2) - c` with `c = 0.00054 sqrt(dim)` (improved consistency
    /// training's choice): quadratic for small errors, linear for large ones, so a few far-off
    /// pairs do not dominate a batch.
    PseudoHuber,
}

variant_names!(Distance, "distance", { L2 = "l2", PseudoHuber = "pseudo-huber" });

/// The pseudo-Huber constant per square root of the dimension (iCT's 0.00054).
pub const PSEUDO_HUBER_C: f64 = 0.00054;

impl Distance {
    /// Per-sample distances [B] between `a` and `b` ([B, dim]).
    pub fn per_sample(self, a: &Tensor, b: &Tensor) -> anyhow::Result<Tensor> {
        let diff = (a - b)?;
        Ok(match self {
            Distance::L2 => diff.sqr()?.mean(D::Minus1)?,
            Distance::PseudoHuber => {
                let dim = diff.dim(D::Minus1)? as f64;
                let c = PSEUDO_HUBER_C * dim.sqrt();
                ((diff.sqr()?.sum(D::Minus1)? + c * c)?.sqrt()? - c)?
            }
        })
    }

    /// The weighted mean over the batch; with all weights 1 and `L2` this is the mean of the
    /// squared error over every element, computed as Algorithm 1's loss always was.
    pub fn weighted_mean(self, a: &Tensor, b: &Tensor, weights: &[f64]) -> anyhow::Result<Tensor> {
        if self == Distance::L2 && weights.iter().all(|&w| w == 1.0) {
            return Ok((a - b)?.sqr()?.mean_all()?);
        }
        let per = self.per_sample(a, b)?;
        let w = column(weights, a.device())?.squeeze(D::Minus1)?;
        Ok((per * w)?.mean_all()?)
    }
}

/// Weight of a training pair of levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LevelWeight {
    /// Every pair counts the same (the paper's lambda = 1).
    Uniform,
    /// `1 / (sigma_high - sigma_low)` (iCT), rescaled so that its mean under the level
    /// sampling is 1 (the loss keeps its scale next to the other terms).
    InverseGap,
}

variant_names!(LevelWeight, "level weight", { Uniform = "uniform", InverseGap = "inverse-gap" });

/// How the higher level of a pair is drawn from the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LevelSampling {
    /// Uniform over the grid's pairs (the paper's).
    Uniform,
    /// iCT's discretized log-normal: pair (high, low) with probability proportional to
    /// `erf((ln high - P_mean) / (sqrt 2 P_std)) - erf((ln low - P_mean) / (sqrt 2 P_std))`,
    /// P_mean -1.1, P_std 2.0.
    LogNormal,
}

variant_names!(LevelSampling, "level sampling", { Uniform = "uniform", LogNormal = "log-normal" });

/// iCT's log-normal level distribution.
pub const LEVEL_P_MEAN: f64 = -1.1;
pub const LEVEL_P_STD: f64 = 2.0;

/// How far apart the two levels of a pair are.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Jump {
    /// `K` grid steps apart, the teacher stepping along the grid (the paper's).
    Adjacent,
    /// The lower level uniform among all levels below the higher one and sigma = 0; the teacher
    /// integrates between them in `K` Heun steps on a Karras sub-grid, and where the lower level
    /// is 0 the target is the teacher's ODE solution itself (consistency-trajectory style).
    Far,
}

variant_names!(Jump, "jump", { Adjacent = "adjacent", Far = "far" });

/// The distillation grid of one phase of training: N Karras levels and the distribution of pairs.
#[derive(Clone, Debug)]
pub struct LevelGrid {
    /// sigma_0 = sigma_max > ... > sigma_{N-1} = sigma_min.
    pub levels: Vec<f64>,
    /// Grid steps between a pair's levels for adjacent jumps.
    pub gap: usize,
    pub jump: Jump,
    /// Cumulative probabilities of the higher level's index (`None`: uniform).
    cdf: Option<Vec<f64>>,
    /// Factor that brings the mean inverse-gap weight to 1.
    inverse_gap_scale: f64,
}

/// A drawn pair of levels per sample: `high` > `low` >= 0 (0 only for far jumps).
#[derive(Clone, Debug, Default)]
pub struct Pairs {
    /// Grid index of the higher level.
    pub high_index: Vec<usize>,
    pub high: Vec<f64>,
    pub low: Vec<f64>,
}

impl LevelGrid {
    /// The grid of `n` levels with pairs `gap` steps apart (adjacent) or far apart.
    pub fn new(
        sig: &SigmaConfig,
        n: usize,
        gap: usize,
        jump: Jump,
        sampling: LevelSampling,
    ) -> anyhow::Result<Self> {
        if gap == 0 || n < gap + 1 {
            bail!("distillation needs 1 <= K < N (got K = {gap}, N = {n})");
        }
        let levels = (0..n)
            .map(|i| sig.karras_sigma(i, n))
            .collect::<Result<Vec<_>, _>>()
            .map_err(sigma_err("distillation levels"))?;
        let mut grid = LevelGrid {
            levels,
            gap,
            jump,
            cdf: None,
            inverse_gap_scale: 1.0,
        };
        if sampling == LevelSampling::LogNormal {
            let erf_at = |s: f64| {
                libm::erf((s.ln() - LEVEL_P_MEAN) / (std::f64::consts::SQRT_2 * LEVEL_P_STD))
            };
            let step = grid.adjacent_span();
            let masses: Vec<f64> = (0..grid.high_choices())
                .map(|j| erf_at(grid.levels[j]) - erf_at(grid.level_or_zero(j + step)))
                .collect();
            let total: f64 = masses.iter().sum();
            let mut acc = 0.0;
            grid.cdf = Some(
                masses
                    .iter()
                    .map(|m| {
                        acc += m / total;
                        acc
                    })
                    .collect(),
            );
        }
        grid.inverse_gap_scale = 1.0 / grid.mean_inverse_gap();
        Ok(grid)
    }

    /// How many indices the higher level can take.
    fn high_choices(&self) -> usize {
        match self.jump {
            Jump::Adjacent => self.levels.len() - self.gap,
            // Every level but the last has something below it (at least sigma = 0).
            Jump::Far => self.levels.len(),
        }
    }

    /// Grid steps that the log-normal mass of a higher index spans.
    fn adjacent_span(&self) -> usize {
        match self.jump {
            Jump::Adjacent => self.gap,
            Jump::Far => 1,
        }
    }

    fn probability(&self, j: usize) -> f64 {
        match &self.cdf {
            None => 1.0 / self.high_choices() as f64,
            Some(cdf) => cdf[j] - if j == 0 { 0.0 } else { cdf[j - 1] },
        }
    }

    /// The level below index `j` for index `i` of the lower choices (far jumps: `i == N - j - 1`
    /// is sigma = 0).
    fn level_or_zero(&self, i: usize) -> f64 {
        self.levels.get(i).copied().unwrap_or(0.0)
    }

    /// The mean of `1 / (high - low)` under the pair distribution.
    fn mean_inverse_gap(&self) -> f64 {
        (0..self.high_choices())
            .map(|j| {
                let p = self.probability(j);
                match self.jump {
                    Jump::Adjacent => p / (self.levels[j] - self.levels[j + self.gap]),
                    Jump::Far => {
                        let below = self.levels.len() - j;
                        (j + 1..=self.levels.len())
                            .map(|i| p / below as f64 / (self.levels[j] - self.level_or_zero(i)))
                            .sum()
                    }
                }
            })
            .sum()
    }

    /// Draws one pair per sample. Uniform adjacent draws take one `below` per sample, as
    /// Algorithm 1's sampler always did (the same stream gives the same pairs).
    pub fn draw(&self, size: usize, rng: &mut HostRng) -> Pairs {
        let mut pairs = Pairs::default();
        for _ in 0..size {
            let j = match &self.cdf {
                None => rng.below(self.high_choices()),
                Some(cdf) => {
                    let u = rng.uniform();
                    cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
                }
            };
            let low = match self.jump {
                Jump::Adjacent => self.levels[j + self.gap],
                Jump::Far => self.level_or_zero(j + 1 + rng.below(self.levels.len() - j)),
            };
            pairs.high_index.push(j);
            pairs.high.push(self.levels[j]);
            pairs.low.push(low);
        }
        pairs
    }

    /// Per-pair loss weights.
    pub fn weights(&self, pairs: &Pairs, weight: LevelWeight) -> Vec<f64> {
        match weight {
            LevelWeight::Uniform => vec![1.0; pairs.high.len()],
            LevelWeight::InverseGap => pairs
                .high
                .iter()
                .zip(&pairs.low)
                .map(|(h, l)| self.inverse_gap_scale / (h - l))
                .collect(),
        }
    }
}

/// A curriculum on N (iCT): N starts at `start` and doubles in equal stages of training until
/// it reaches `end`; `start == end` is a fixed grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelCurriculum {
    pub start: usize,
    pub end: usize,
    pub total_steps: usize,
}

impl LevelCurriculum {
    /// N at training step `step` (0-based).
    pub fn levels_at(&self, step: usize) -> usize {
        if self.start >= self.end {
            return self.end;
        }
        let doublings = (self.end as f64 / self.start as f64).log2().ceil() as usize;
        let stage = self.total_steps.div_ceil(doublings + 1).max(1);
        let n = self.start.saturating_mul(1usize << (step / stage).min(30));
        n.min(self.end)
    }
}

/// `count` Karras-spaced levels from `high` down to `low` (both included; `low` may be 0), per
/// row: the sub-grid a far jump's teacher integrates on.
pub fn sub_grid(high: &[f64], low: &[f64], count: usize, rho: f64) -> Vec<Vec<f64>> {
    (0..=count)
        .map(|s| {
            high.iter()
                .zip(low)
                .map(|(&h, &l)| {
                    let t = s as f64 / count as f64;
                    let (a, b) = (h.powf(1.0 / rho), l.powf(1.0 / rho));
                    (a + t * (b - a)).powf(rho)
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests;
