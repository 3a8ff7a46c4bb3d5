//! The int8 student as a closed-loop policy: frmd-core's [`frmd_core::policy::Policy`] over the
//! network of an exported blob of any backbone ([`LoadedBlob`], told apart by its magic): the
//! firmware's own code path, blob loader included.
//!
//! Any exported shape runs: the policy's buffers have the host capacities of
//! [`frmd_export::host`] and the blob's descriptor gives the sizes at run time. The blob is owned
//! next to its loaded view, and the policy next to both ([`self_cell`]), so nothing is leaked and
//! nothing is rebuilt per chunk: the network is validated once, as on the firmware, and every
//! chunk starts a fresh episode with [`frmd_core::policy::Policy::reset`]. On CPUs whose
//! kernels run packed weights ([`frmd_core::kernels::packed`]) the MLP's weights are packed once
//! here and owned beside the blob. The f32 twin, a
//! comparison tool, builds its f32 network per chunk.
use crate::tasks::{Policy, PolicyInput};
use anyhow::{bail, Context};
use frmd_core::blob::{AlignedBlob, LoadedBlob};
use frmd_core::policy::{Network, Noise, PolicyDims, PolicyError};
use frmd_core::rng::Rng;
use frmd_export::host::{
    act_blob, check_capacity, packed_weights, BlobPolicy, HostPolicy, HostScratch, HostTrajectory,
    HostWork, MAX_WIDTH,
};
use frmd_export::ExportedStudent;
use std::path::Path;

/// One chunk of `policy` from raw inputs: a fresh episode with the observation history and the
/// last commanded action and rate of `input`; the positions `[n][k]` in raw units.
/// `act` is the policy's [`frmd_core::policy::Policy::act`], or for a blob policy
/// [`frmd_export::host::act_blob`] (the same call, compiled optimized in every profile).
fn run_chunk<'a, Net: Network>(
    policy: &mut HostPolicy<'a, Net>,
    input: &PolicyInput<'_>,
    noise: Noise<'_>,
    act: for<'p, 'n> fn(
        &'p mut HostPolicy<'a, Net>,
        Noise<'n>,
    ) -> Result<&'p HostTrajectory, PolicyError>,
) -> anyhow::Result<Vec<Vec<f32>>> {
    let dims = policy.dims();
    if input.obs_history.len() != dims.history {
        bail!(
            "int8 policy expects an observation history of {}, got {}",
            dims.history,
            input.obs_history.len()
        );
    }
    policy.reset(input.prev_action).context("reset")?;
    for obs in input.obs_history {
        policy.observe(obs).context("observe")?;
    }
    policy
        .set_previous_action(input.prev_action, input.prev_rate)
        .context("previous action")?;
    let chunk = act(policy, noise).context("act")?;
    let (positions, _) = chunk
        .values(dims.horizon * dims.action_dim)
        .context("chunk")?;
    Ok(positions
        .chunks(dims.action_dim)
        .map(<[f32]>::to_vec)
        .collect())
}

self_cell::self_cell!(
    /// A blob and its checked view.
    struct Loaded {
        owner: AlignedBlob,
        #[covariant]
        dependent: LoadedBlob,
    }
);

/// A loaded blob and its weights packed for this CPU's kernels (empty where they run the
/// row-major weights).
struct Packed {
    loaded: Loaded,
    weights: Vec<u8>,
}

self_cell::self_cell!(
    /// A loaded blob and the policy built over it once.
    struct Ready {
        owner: Packed,
        #[not_covariant]
        dependent: BlobPolicy,
    }
);

impl Ready {
    fn blob(&self) -> &LoadedBlob<'_> {
        self.borrow_owner().loaded.borrow_dependent()
    }
}

/// What runs a chunk: the blob's int8 policy, or the blob's policy around the f32 network of the
/// export it came from ([`Int8Policy::f32_twin`]).
enum Runner {
    Int8(Box<Ready>),
    F32Twin {
        blob: Loaded,
        scratch: Box<HostScratch>,
        student: Box<ExportedStudent>,
    },
}

impl Runner {
    fn blob(&self) -> &LoadedBlob<'_> {
        match self {
            Self::Int8(ready) => ready.blob(),
            Self::F32Twin { blob, .. } => blob.borrow_dependent(),
        }
    }

    fn run(&mut self, input: &PolicyInput<'_>, noise: Noise<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        match self {
            Self::Int8(ready) => {
                ready.with_dependent_mut(|_, policy| run_chunk(policy, input, noise, act_blob))
            }
            Self::F32Twin {
                blob,
                scratch,
                student,
            } => {
                let loaded = blob.borrow_dependent();
                student.with_f32_network(scratch, |network| {
                    run_chunk(
                        &mut HostPolicy::new(loaded.config(), network)?,
                        input,
                        noise,
                        HostPolicy::act,
                    )
                })
            }
        }
    }
}

/// Loads `bytes` with frmd-core's loader, checking the shape against the host capacities.
fn load(bytes: &[u8]) -> anyhow::Result<Loaded> {
    let blob = Loaded::try_new(AlignedBlob::new(bytes), |b| LoadedBlob::load(b.bytes()))
        .context("loading the blob")?;
    check_capacity(&blob.borrow_dependent().dims())?;
    Ok(blob)
}

/// The int8 student behind the evaluation [`Policy`] trait; noise from `frmd_core::rng::Rng`
/// seeded by the episode seed, as the float policies.
pub struct Int8Policy {
    runner: Runner,
    rng: Rng,
    label: String,
}

impl Int8Policy {
    /// The policy of an exported blob (MLP or transformer, by its magic).
    pub fn from_blob(bytes: &[u8], label: &str) -> anyhow::Result<Self> {
        let loaded = load(bytes)?;
        let weights = packed_weights(loaded.borrow_dependent())?;
        let ready = Ready::try_new(Packed { loaded, weights }, |packed| -> anyhow::Result<_> {
            let blob = packed.loaded.borrow_dependent();
            let mut network = blob.network::<MAX_WIDTH, _>(HostWork::new())?;
            network.use_packed_weights(&packed.weights)?;
            Ok(HostPolicy::new(blob.config(), network)?)
        })?;
        Ok(Self::new(Runner::Int8(Box::new(ready)), label))
    }

    /// The same runtime policy as [`Self::from_blob`] with frmd-core's f32 network of `student`
    /// (the export the blob came from) in place of the int8 one: isolates quantization from
    /// everything else in closed-loop comparisons.
    pub fn f32_twin(bytes: &[u8], student: ExportedStudent, label: &str) -> anyhow::Result<Self> {
        let runner = Runner::F32Twin {
            blob: load(bytes)?,
            scratch: Box::new(HostScratch::new()),
            student: Box::new(student),
        };
        Ok(Self::new(runner, label))
    }

    fn new(runner: Runner, label: &str) -> Self {
        Int8Policy {
            runner,
            rng: Rng::new(0),
            label: label.into(),
        }
    }

    /// Loads a blob file (MLP or transformer, by its magic), named by its activations' precision
    /// (`int8` or `int16`).
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let mut policy =
            Self::from_blob(&bytes, "").with_context(|| format!("loading {}", path.display()))?;
        policy.label = format!("int{}", policy.runner.blob().activation_bits());
        Ok(policy)
    }

    /// The policy's sizes (from the blob).
    pub fn dims(&self) -> PolicyDims {
        self.runner.blob().dims()
    }

    /// Observation history the policy needs.
    pub fn history(&self) -> usize {
        self.dims().history
    }

    /// One chunk with explicit noise (`steps * n * k` standard-normal values).
    pub fn run_with_noise(
        &mut self,
        input: &PolicyInput<'_>,
        noise: &[f32],
    ) -> anyhow::Result<Vec<Vec<f32>>> {
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

    fn horizon(&self) -> Option<usize> {
        Some(self.dims().horizon)
    }
}
