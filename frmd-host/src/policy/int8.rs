//! The int8 student as a closed-loop policy: frmd-core's [`frmd_core::policy::Policy`] over an
//! [`frmd_core::blob::LoadedPolicy`] (the firmware's own code path, blob loader included).
//!
//! frmd-core's policy is generic over its sizes (history M, observation O, action K, horizon N,
//! ProDMP parameters per DoF P), so the host compiles it for a fixed list of shapes
//! ([`SHAPES`]: the built-in tasks with the default training config, plus the small shape the
//! end-to-end test trains) and picks the one the blob's descriptor names. The blob bytes are
//! leaked once per loaded policy (the loaded policy borrows them for `'static`).
use crate::eval::policy::{Policy, PolicyInput};
use anyhow::{bail, Context};
use frmd_core::blob::LoadedPolicy;
use frmd_core::policy::{F32Network, Network, Noise, Policy as CorePolicy};
use frmd_export::fold::FoldedMlp;
use frmd_core::rng::Rng;
use frmd_export::fold::MAX_WIDTH;
use std::path::Path;

/// One chunk from raw inputs with explicit noise; sizes are checked at run time.
pub trait ChunkRunner {
    /// (history, obs_dim, action_dim, horizon, params per DoF).
    fn shape(&self) -> [usize; 5];
    /// Positions `[n][k]` in raw units for raw `history`, `prev_action`, `prev_rate` (units/s).
    fn run(&mut self, input: &PolicyInput<'_>, noise: Noise<'_>) -> anyhow::Result<Vec<Vec<f32>>>;
}

pub(crate) struct Runner<Net, const M: usize, const O: usize, const K: usize, const N: usize, const P: usize> {
    pub(crate) policy: CorePolicy<'static, Net, M, O, K, N, P, MAX_WIDTH>,
}

fn array<const L: usize>(values: &[f32], what: &str) -> anyhow::Result<[f32; L]> {
    values.try_into().map_err(|_| anyhow::anyhow!("{what} has {} values, the policy expects {L}", values.len()))
}

impl<Net: Network, const M: usize, const O: usize, const K: usize, const N: usize, const P: usize> ChunkRunner
    for Runner<Net, M, O, K, N, P>
{
    fn shape(&self) -> [usize; 5] {
        [M, O, K, N, P]
    }

    fn run(&mut self, input: &PolicyInput<'_>, noise: Noise<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        if input.obs_history.len() != M {
            bail!("int8 policy expects an observation history of {M}, got {}", input.obs_history.len());
        }
        let prev = array::<K>(input.prev_action, "previous action")?;
        let rate = array::<K>(input.prev_rate, "previous rate")?;
        let err = |e: frmd_core::policy::PolicyError| anyhow::anyhow!("int8 policy: {e}");
        self.policy.reset(&prev).map_err(err)?;
        for obs in input.obs_history {
            self.policy.observe(&array::<O>(obs, "observation")?).map_err(err)?;
        }
        self.policy.set_previous_action(&prev, &rate).map_err(err)?;
        let chunk = self.policy.act(noise).map_err(err)?;
        Ok(chunk.positions.iter().map(|a| a.to_vec()).collect())
    }
}

pub(crate) fn leak_aligned(bytes: &[u8]) -> &'static [u8] {
    let mut words = vec![0u32; bytes.len().div_ceil(4)];
    bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
    let words: &'static [u32] = Box::leak(words.into_boxed_slice());
    &bytemuck::cast_slice(words)[..bytes.len()]
}

fn try_shape<const M: usize, const O: usize, const K: usize, const N: usize, const P: usize>(
    bytes: &'static [u8],
    f32_twin: Option<&'static FoldedMlp>,
) -> Option<anyhow::Result<Box<dyn ChunkRunner>>> {
    let loaded = match LoadedPolicy::<M, O, K, N, P>::load(bytes) {
        Ok(l) => l,
        Err(frmd_core::blob::BlobError::DimensionMismatch(_)) => return None,
        Err(e) => return Some(Err(anyhow::anyhow!("blob: {e}"))),
    };
    let loaded: &'static LoadedPolicy<'static, M, O, K, N, P> = Box::leak(Box::new(loaded));
    Some(match f32_twin {
        None => loaded
            .policy::<MAX_WIDTH, MAX_WIDTH>()
            .map(|policy| Box::new(Runner { policy }) as Box<dyn ChunkRunner>)
            .map_err(|e| anyhow::anyhow!("blob policy: {e}")),
        Some(folded) => {
            let biases: &'static [f32] = Box::leak(folded.flat_first_layer_biases().into_boxed_slice());
            folded.f32_network::<MAX_WIDTH>(biases).and_then(|net: F32Network<'static, MAX_WIDTH>| {
                CorePolicy::<'static, _, M, O, K, N, P, MAX_WIDTH>::new(loaded.config(), net)
                    .map(|policy| Box::new(Runner { policy }) as Box<dyn ChunkRunner>)
                    .map_err(|e| anyhow::anyhow!("f32 policy: {e}"))
            })
        }
    })
}

/// Shapes (M, O, K, N, P) the host int8 runner is compiled for.
pub const SHAPES: &[[usize; 5]] = &[[2, 6, 2, 12, 21], [2, 9, 2, 12, 21], [2, 10, 2, 12, 21], [2, 7, 2, 12, 21], [2, 6, 2, 8, 7], [2, 39, 4, 12, 21]];

/// Loads a blob into a runner of the matching compiled shape.
/// With `f32_twin`, the policy runs frmd-core's f32 network of the folded model instead of the
/// blob's int8 network (same blob config: normalization, steps, decoder, layout).
pub fn load_runner(bytes: &[u8], f32_twin: Option<FoldedMlp>) -> anyhow::Result<Box<dyn ChunkRunner>> {
    let bytes = leak_aligned(bytes);
    let twin: Option<&'static FoldedMlp> = f32_twin.map(|f| &*Box::leak(Box::new(f)));
    let found = try_shape::<2, 6, 2, 12, 21>(bytes, twin)
        .or_else(|| try_shape::<2, 9, 2, 12, 21>(bytes, twin))
        .or_else(|| try_shape::<2, 10, 2, 12, 21>(bytes, twin))
        .or_else(|| try_shape::<2, 7, 2, 12, 21>(bytes, twin))
        .or_else(|| try_shape::<2, 6, 2, 8, 7>(bytes, twin))
        // MetaWorld (39 observations, 4 actions) until the any-shape runner lands.
        .or_else(|| try_shape::<2, 39, 4, 12, 21>(bytes, twin));
    match found {
        Some(runner) => runner,
        None => bail!("the blob's sizes are not among the host's compiled int8 shapes (M, O, K, N, P) {SHAPES:?}"),
    }
}

/// The int8 student behind the evaluation [`Policy`] trait; noise from `frmd_core::rng::Rng`
/// seeded by the episode seed, as the float policies.
pub struct Int8Policy {
    runner: Box<dyn ChunkRunner>,
    rng: Rng,
    label: String,
}

impl Int8Policy {
    pub fn from_blob(bytes: &[u8], label: &str) -> anyhow::Result<Self> {
        Ok(Int8Policy { runner: load_runner(bytes, None)?, rng: Rng::new(0), label: label.into() })
    }

    /// The same runtime policy with frmd-core's f32 network of `folded` in place of the int8 one
    /// (isolates quantization from everything else in closed-loop comparisons).
    pub fn f32_twin(bytes: &[u8], folded: FoldedMlp, label: &str) -> anyhow::Result<Self> {
        Ok(Int8Policy { runner: load_runner(bytes, Some(folded))?, rng: Rng::new(0), label: label.into() })
    }

    /// A policy over any runner (e.g. [`super::transformer::load_runner`]).
    pub fn from_runner(runner: Box<dyn ChunkRunner>, label: &str) -> Self {
        Int8Policy { runner, rng: Rng::new(0), label: label.into() }
    }

    /// Loads a blob file (MLP `FRMD` or transformer `FRMT`, by its magic).
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        super::transformer::int8_policy(&bytes, "int8").with_context(|| format!("loading {}", path.display()))
    }

    /// (history, obs_dim, action_dim, horizon, params per DoF) of the loaded blob.
    pub fn shape(&self) -> [usize; 5] {
        self.runner.shape()
    }

    /// Observation history the policy needs.
    pub fn history(&self) -> usize {
        self.runner.shape()[0]
    }

    /// One chunk with explicit noise (`steps * n * k` standard-normal values).
    pub fn run_with_noise(&mut self, input: &PolicyInput<'_>, noise: &[f32]) -> anyhow::Result<Vec<Vec<f32>>> {
        self.runner.run(input, Noise::Given(noise))
    }
}

impl Policy for Int8Policy {
    fn name(&self) -> String {
        self.label.clone()
    }

    fn reset(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        self.runner.run(input, Noise::Rng(&mut self.rng))
    }
}
