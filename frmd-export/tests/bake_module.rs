//! Compiles the committed baked module (`tests/baked/`, kept current by `bake_golden.rs`) the way a
//! firmware crate would (`include!`), and checks it against the blob of the same policy.

#[allow(dead_code)]
mod baked {
    include!("baked/policy.rs");
}

use frmd_core::blob::{AlignedBlob, LoadedMlp};
use frmd_core::policy::Noise;
use frmd_core::rng::Rng;
use frmd_test_support::random_policy::*;

#[test]
fn baked_module_runs_bit_identical_to_the_blob() {
    let policy = sample_policy(GOLDEN_SEED, GOLDEN_STEPS);
    let blob = AlignedBlob::new(&policy.blob().unwrap());
    let loaded = LoadedMlp::load(blob.bytes()).unwrap();
    let mut from_blob = loaded
        .policy::<M, O, K, N, P, { baked::INPUT_WIDTH }, { baked::SCRATCH_WIDTH }>()
        .unwrap();
    let mut from_module = baked::policy(&mut baked::Storage::new()).unwrap();
    for seed in 0..4 {
        for p in [&mut from_blob as &mut dyn Runner, &mut from_module] {
            p.start();
        }
        let a = *from_blob.act(Noise::Rng(&mut Rng::new(seed))).unwrap();
        let b = *from_module.act(Noise::Rng(&mut Rng::new(seed))).unwrap();
        assert_eq!(a, b, "seed {seed}");
        assert_eq!(
            from_blob.network().accumulators(),
            from_module.network().accumulators()
        );
    }
    assert_eq!(baked::STEPS.len(), GOLDEN_STEPS);
    assert_eq!(baked::SCRATCH_WIDTH, policy.scratch_width());
    let memory = policy.memory();
    assert_eq!(baked::FLASH_BYTES, memory.flash_bytes());
    assert_eq!(baked::WEIGHTS_BYTES, baked::WEIGHTS.0.len());
    assert!(baked::POLICY_RAM_BYTES >= memory.state_bytes + memory.scratch_bytes);
    std::println!(
        "baked sample policy: flash {} B (weights {} + tables {}), policy RAM {} B (scratch {}, state {})",
        baked::FLASH_BYTES,
        baked::WEIGHTS_BYTES,
        baked::TABLE_BYTES,
        baked::POLICY_RAM_BYTES,
        baked::SCRATCH_BYTES,
        baked::STATE_BYTES
    );
}

/// Same episode start for both policy types.
trait Runner {
    fn start(&mut self);
}

impl<Net: frmd_core::policy::Network, const I: usize> Runner
    for frmd_core::policy::Policy<'_, Net, M, O, K, N, P, I>
{
    fn start(&mut self) {
        self.reset(&[0.1, -0.1, 0.2]).unwrap();
        self.observe(&[0.3, 1.5, 0.5, -1.0]).unwrap();
        self.observe(&[0.2, 1.2, 0.5, -0.5]).unwrap();
    }
}
