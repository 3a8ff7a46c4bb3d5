//! The int8 student as a closed-loop policy: frmd-core's [`frmd_core::policy::Policy`] over the
//! network of an exported blob, MLP ([`LoadedMlp`]) or transformer-lite ([`LoadedTransformer`]),
//! chosen by the blob's magic: the firmware's own code path, blob loader included.
//!
//! Any exported shape runs: the policy's buffers have the fixed host capacities below (heapless
//! style) and the blob's descriptor gives the sizes at run time. The blob is owned next to the
//! policy that borrows it ([`self_cell`]), so nothing is leaked. An MLP policy is built once per
//! load; a transformer's network and policy are built per chunk from the loaded blob (a few
//! microseconds against a chunk of about a millisecond), with the scratch kept across chunks.
use crate::tasks::{Policy, PolicyInput};
use anyhow::{bail, Context};
use frmd_core::blob::{LoadedMlp, LoadedTransformer, TRANSFORMER_MAGIC};
use frmd_core::policy::{
    F32MlpNetwork, F32TransformerNetwork, Int8MlpNetwork, Network, Noise, Policy as CorePolicy,
    PolicyDims, PolicyError,
};
use frmd_core::prodmp::MAX_NUM_BASIS;
use frmd_core::rng::Rng;
use frmd_export::fold::{FoldedMlp, MAX_WIDTH};
use frmd_export::transformer::{FoldedTransformer, HostScratch};
use std::path::Path;

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

/// frmd-core's policy with the host capacities (the model input up to the exporter's widest
/// layer).
type HostPolicy<'a, Net> = CorePolicy<
    'a,
    Net,
    MAX_HISTORY,
    MAX_OBS_DIM,
    MAX_ACTION_DIM,
    MAX_HORIZON,
    MAX_PARAMS_PER_DOF,
    MAX_WIDTH,
>;

/// A blob copied into 4-aligned memory (the loaders read it in place).
pub struct Blob {
    words: Vec<u32>,
    len: usize,
}

impl Blob {
    pub fn new(bytes: &[u8]) -> Self {
        let mut words = vec![0u32; bytes.len().div_ceil(4)];
        bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
        Blob {
            words,
            len: bytes.len(),
        }
    }

    pub fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.words)[..self.len]
    }

    /// Whether this is a transformer blob (magic `FRMT`).
    pub fn is_transformer(&self) -> bool {
        self.bytes().get(..4) == Some(&TRANSFORMER_MAGIC[..])
    }
}

/// A blob whose sizes exceed the host's capacities is refused with its own shape.
fn check_host_capacity(d: &PolicyDims) -> anyhow::Result<()> {
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

fn policy_error(what: &'static str) -> impl Fn(PolicyError) -> anyhow::Error {
    move |e| anyhow::anyhow!("{what}: {e}")
}

/// One chunk of `policy` from raw inputs: a fresh episode with the observation history and the
/// last commanded action and rate of `input`; the positions `[n][k]` in raw units.
fn run_chunk<Net: Network>(
    policy: &mut HostPolicy<'_, Net>,
    input: &PolicyInput<'_>,
    noise: Noise<'_>,
) -> anyhow::Result<Vec<Vec<f32>>> {
    let dims = policy.dims();
    if input.obs_history.len() != dims.history {
        bail!(
            "int8 policy expects an observation history of {}, got {}",
            dims.history,
            input.obs_history.len()
        );
    }
    let err = policy_error("int8 policy");
    policy.reset(input.prev_action).map_err(&err)?;
    for obs in input.obs_history {
        policy.observe(obs).map_err(&err)?;
    }
    policy
        .set_previous_action(input.prev_action, input.prev_rate)
        .map_err(&err)?;
    let chunk = policy.act(noise).map_err(&err)?;
    let (positions, _) = chunk
        .values(dims.horizon * dims.action_dim)
        .context("chunk")?;
    Ok(positions
        .chunks(dims.action_dim)
        .map(<[f32]>::to_vec)
        .collect())
}

type MlpPolicy<'a> = HostPolicy<'a, Int8MlpNetwork<'a, MAX_WIDTH>>;
type MlpF32Policy<'a> = HostPolicy<'a, F32MlpNetwork<'a, MAX_WIDTH>>;

self_cell::self_cell!(
    /// An MLP blob and its int8 policy.
    struct MlpRunner {
        owner: Blob,
        #[covariant]
        dependent: MlpPolicy,
    }
);

/// An MLP blob, the folded float model and its first-layer bias variants.
struct MlpTwin {
    blob: Blob,
    folded: FoldedMlp,
    biases: Vec<f32>,
}

self_cell::self_cell!(
    /// The blob's policy over frmd-core's f32 network of the folded model.
    struct MlpF32Runner {
        owner: MlpTwin,
        #[covariant]
        dependent: MlpF32Policy,
    }
);

self_cell::self_cell!(
    /// A transformer blob, loaded.
    struct TransformerBlob {
        owner: Blob,
        #[covariant]
        dependent: LoadedTransformer,
    }
);

/// The network a policy runs on.
enum Runner {
    Mlp(MlpRunner),
    MlpF32(MlpF32Runner),
    Transformer {
        blob: TransformerBlob,
        scratch: Box<HostScratch>,
        f32_twin: Option<Box<FoldedTransformer>>,
    },
}

impl Runner {
    fn new(bytes: &[u8]) -> anyhow::Result<Self> {
        let blob = Blob::new(bytes);
        if blob.is_transformer() {
            let blob = TransformerBlob::try_new(blob, |b| LoadedTransformer::load(b.bytes()))
                .map_err(|e| anyhow::anyhow!("transformer blob: {e}"))?;
            check_host_capacity(&blob.borrow_dependent().dims())?;
            return Ok(Runner::Transformer {
                blob,
                scratch: Box::new(HostScratch::new()),
                f32_twin: None,
            });
        }
        let runner = MlpRunner::try_new(blob, |b| {
            let loaded = LoadedMlp::load(b.bytes()).map_err(|e| anyhow::anyhow!("blob: {e}"))?;
            check_host_capacity(&loaded.dims())?;
            loaded.policy().map_err(policy_error("blob policy"))
        })?;
        Ok(Runner::Mlp(runner))
    }

    fn dims(&self) -> PolicyDims {
        match self {
            Runner::Mlp(runner) => runner.borrow_dependent().dims(),
            Runner::MlpF32(runner) => runner.borrow_dependent().dims(),
            Runner::Transformer { blob, .. } => blob.borrow_dependent().dims(),
        }
    }

    fn run(&mut self, input: &PolicyInput<'_>, noise: Noise<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        match self {
            Runner::Mlp(runner) => {
                runner.with_dependent_mut(|_, policy| run_chunk(policy, input, noise))
            }
            Runner::MlpF32(runner) => {
                runner.with_dependent_mut(|_, policy| run_chunk(policy, input, noise))
            }
            Runner::Transformer {
                blob,
                scratch,
                f32_twin,
            } => {
                let loaded = blob.borrow_dependent();
                let err = policy_error("transformer policy");
                match f32_twin {
                    None => {
                        let network = loaded.network(&mut **scratch).map_err(&err)?;
                        run_chunk(
                            &mut HostPolicy::new(loaded.config(), network).map_err(&err)?,
                            input,
                            noise,
                        )
                    }
                    Some(folded) => {
                        let blocks = folded.f32_blocks();
                        let tokens = folded.flat_noise_tokens();
                        let network = F32TransformerNetwork::new(
                            folded.view(&blocks, 0)?,
                            &folded.layout,
                            &tokens,
                            &mut **scratch,
                        )
                        .map_err(&err)?;
                        run_chunk(
                            &mut HostPolicy::new(loaded.config(), network).map_err(&err)?,
                            input,
                            noise,
                        )
                    }
                }
            }
        }
    }
}

/// The int8 student behind the evaluation [`Policy`] trait; noise from `frmd_core::rng::Rng`
/// seeded by the episode seed, as the float policies.
pub struct Int8Policy {
    runner: Runner,
    rng: Rng,
    label: String,
}

impl Int8Policy {
    /// The policy of an MLP (`FRMD`) or transformer (`FRMT`) blob, chosen by its magic.
    pub fn from_blob(bytes: &[u8], label: &str) -> anyhow::Result<Self> {
        Ok(Int8Policy {
            runner: Runner::new(bytes)?,
            rng: Rng::new(0),
            label: label.into(),
        })
    }

    /// The same runtime policy as [`Self::from_blob`] of an MLP blob with frmd-core's f32
    /// network of `folded` in place of the int8 one (isolates quantization from everything else
    /// in closed-loop comparisons).
    pub fn f32_twin(bytes: &[u8], folded: FoldedMlp, label: &str) -> anyhow::Result<Self> {
        let biases = folded.flat_first_layer_biases();
        let twin = MlpTwin {
            blob: Blob::new(bytes),
            folded,
            biases,
        };
        let runner = MlpF32Runner::try_new(twin, |t| {
            let loaded =
                LoadedMlp::load(t.blob.bytes()).map_err(|e| anyhow::anyhow!("blob: {e}"))?;
            let network = t.folded.f32_network::<MAX_WIDTH>(&t.biases)?;
            HostPolicy::new(loaded.config(), network).map_err(policy_error("f32 policy"))
        })?;
        Ok(Int8Policy {
            runner: Runner::MlpF32(runner),
            rng: Rng::new(0),
            label: label.into(),
        })
    }

    /// [`Self::f32_twin`] of a transformer blob with the f32 reference network of `folded`.
    pub fn transformer_f32_twin(
        bytes: &[u8],
        folded: FoldedTransformer,
        label: &str,
    ) -> anyhow::Result<Self> {
        let mut policy = Self::from_blob(bytes, label).context("f32 twin")?;
        match &mut policy.runner {
            Runner::Transformer { f32_twin, .. } => *f32_twin = Some(Box::new(folded)),
            _ => bail!(
                "not a transformer blob (magic {:?}, expected FRMT)",
                bytes.get(..4)
            ),
        }
        Ok(policy)
    }

    /// Loads a blob file (MLP or transformer, by its magic).
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        Self::from_blob(&bytes, "int8").with_context(|| format!("loading {}", path.display()))
    }

    /// The policy's sizes (from the blob).
    pub fn dims(&self) -> PolicyDims {
        self.runner.dims()
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
