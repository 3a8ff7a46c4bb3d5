//! How std programs run an exported student with frmd-core: the capacities of the host policy's
//! buffers (heapless style: any exported shape up to these runs without a code change, the blob's
//! descriptor gives the sizes at run time), the transformer scratch, and [`check_blob`], which an
//! export passes before anything is written.
use anyhow::{bail, Context};
use frmd_core::blob::{AlignedBlob, BlobNetwork, LoadedBlob};
use frmd_core::kernels::Precision;
use frmd_core::model::transformer::{TransformerBuffers, TransformerScratch};
use frmd_core::policy::{Noise, Policy, PolicyDims, PolicyError, Trajectory, TransformerWork};
use frmd_core::prodmp::MAX_NUM_BASIS;

/// Longest observation history the host runs.
pub const MAX_HISTORY: usize = 16;
/// Largest observation dimension the host runs.
pub const MAX_OBS_DIM: usize = 128;
/// Largest action dimension (DoF) the host runs.
pub const MAX_ACTION_DIM: usize = 32;
/// Longest horizon the host runs.
pub const MAX_HORIZON: usize = 64;
/// Most ProDMP parameters per DoF (the decoder's limit).
pub const MAX_PARAMS_PER_DOF: usize = MAX_NUM_BASIS + 1;
/// Widest MLP layer (and model input) the exporter's f32 path and the host policies handle.
pub const MAX_WIDTH: usize = 1024;

/// frmd-core's policy with the host capacities (the model input up to [`MAX_WIDTH`]).
pub type HostPolicy<'a, Net> = Policy<
    'a,
    Net,
    MAX_HISTORY,
    MAX_OBS_DIM,
    MAX_ACTION_DIM,
    MAX_HORIZON,
    MAX_PARAMS_PER_DOF,
    MAX_WIDTH,
>;

/// frmd-core's policy over a loaded blob of any backbone and precision, with the host
/// capacities: what `frmd` runs for an exported student.
pub type BlobPolicy<'a> = HostPolicy<'a, BlobNetwork<'a, MAX_WIDTH, HostWork>>;

/// A chunk of a host policy (positions and velocities up to the host capacities).
pub type HostTrajectory = Trajectory<MAX_HORIZON, MAX_ACTION_DIM>;

/// One chunk of a blob policy ([`Policy::act`]). Not generic on purpose: the chunk's code
/// (sampler, network glue, decode; frmd-core's generics) is compiled in this crate, which every
/// profile optimizes (`opt-level = 3` in the dev profile too, see the workspace Cargo.toml), and
/// not in a caller built with `opt-level = 1` (frmd-host in the dev profile, where the same
/// chunk took 10.0 us against 7.3 us in release: docs/design.md section 8).
#[inline(never)]
pub fn act_blob<'p>(
    policy: &'p mut BlobPolicy<'_>,
    noise: Noise<'_>,
) -> Result<&'p HostTrajectory, PolicyError> {
    policy.act(noise)
}

/// Scratch for the host's transformer passes with `P` codes (enough for the `transformer`
/// backbone, 6 x 256 with horizon 16): floats, codes, accumulators.
pub type HostScratchOf<P> = TransformerScratch<HOST_FLOATS, HOST_CODES, HOST_ACCUMULATORS, P>;
/// Scratch for the host's f32 and int8 transformer passes.
pub type HostScratch = HostScratchOf<i8>;
pub(crate) const HOST_FLOATS: usize = 32_768;
pub(crate) const HOST_CODES: usize = 16_384;
pub(crate) const HOST_ACCUMULATORS: usize = 1_024;

/// Working memory for a transformer of either activation precision (what
/// [`LoadedBlob::network`] takes): an int8 and an int16 scratch, each allocated on the heap when
/// a network first asks for it (an MLP never does).
#[derive(Debug, Default)]
pub struct HostWork {
    int8: Option<Box<HostScratch>>,
    int16: Option<Box<HostScratchOf<i16>>>,
}

impl HostWork {
    /// No scratch yet.
    pub fn new() -> Self {
        Self::default()
    }
}

impl TransformerWork<i8> for HostWork {
    fn buffers(&mut self) -> TransformerBuffers<'_, i8> {
        self.int8.get_or_insert_with(boxed_scratch).buffers()
    }
}

impl TransformerWork<i16> for HostWork {
    fn buffers(&mut self) -> TransformerBuffers<'_, i16> {
        self.int16.get_or_insert_with(boxed_scratch).buffers()
    }
}

/// A zeroed host scratch of `P` codes on the heap.
pub(crate) fn boxed_scratch<P: Precision>() -> Box<HostScratchOf<P>> {
    Box::new(HostScratchOf::new())
}

/// The packed copy of `blob`'s network weights for this CPU's kernels
/// ([`frmd_core::kernels::packed`], handed to [`BlobNetwork::use_packed_weights`]): empty where
/// they would not run it (no VNNI level here, or a transformer).
pub fn packed_weights(blob: &LoadedBlob<'_>) -> anyhow::Result<Vec<u8>> {
    if !frmd_core::kernels::packed::runs_here() {
        return Ok(Vec::new());
    }
    let network = blob
        .network::<MAX_WIDTH, _>(HostWork::new())
        .context("the blob's network")?;
    let mut bytes = vec![0; network.packed_len()];
    network
        .pack_weights(&mut bytes)
        .context("packing the weights")?;
    Ok(bytes)
}

/// Refuses a policy whose sizes exceed the host's capacities, naming its shape.
pub fn check_capacity(d: &PolicyDims) -> anyhow::Result<()> {
    let limits = [
        ("history", d.history, MAX_HISTORY),
        ("obs_dim", d.obs_dim, MAX_OBS_DIM),
        ("action_dim", d.action_dim, MAX_ACTION_DIM),
        ("horizon", d.horizon, MAX_HORIZON),
        ("params_per_dof", d.params_per_dof, MAX_PARAMS_PER_DOF),
    ];
    if let Some((field, value, max)) = limits.iter().find(|(_, v, max)| v > max) {
        bail!(
            "blob shape history {} obs_dim {} action_dim {} horizon {} params_per_dof {}: the host runs {field} up to {max}, not {value}",
            d.history, d.obs_dim, d.action_dim, d.horizon, d.params_per_dof
        );
    }
    Ok(())
}

/// Loads `blob` with frmd-core's loader (the firmware's) and builds its policy with the host
/// capacities: a blob the runtime would refuse is an error here. Returns the policy's sizes.
pub fn check_blob(blob: &[u8]) -> anyhow::Result<PolicyDims> {
    let aligned = AlignedBlob::new(blob);
    let loaded = LoadedBlob::load(aligned.bytes()).context("loading the blob")?;
    let dims = loaded.dims();
    check_capacity(&dims)?;
    let mut work = HostWork::new();
    let network = loaded
        .network::<MAX_WIDTH, _>(&mut work)
        .context("the blob's network")?;
    HostPolicy::new(loaded.config(), network).context("the blob's policy")?;
    Ok(dims)
}
