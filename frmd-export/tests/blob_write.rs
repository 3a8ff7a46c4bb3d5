//! The exporter's blob round-trips through frmd-core's loader into a working policy.

use frmd_core::blob::{AlignedBlob, BlobError, LoadedMlp, MlpSection, PolicySection};
use frmd_core::policy::Noise;
use frmd_core::rng::Rng;
use frmd_test_support::random_policy::*;

#[test]
fn written_blob_loads_and_matches_the_parts() {
    for steps in [1, 3] {
        let policy = sample_policy(5, steps);
        let blob = AlignedBlob::new(&policy.blob().unwrap());
        let loaded = LoadedMlp::load(blob.bytes()).unwrap();
        assert_eq!(loaded.steps(), &policy.steps[..]);
        assert_eq!(loaded.layout(), &policy.layout);
        assert_eq!(loaded.decoder().pos_params, &policy.prodmp.pos_params[..]);
        assert_eq!(loaded.decoder().vel_v0.to_vec(), policy.prodmp.vel_v0);
        let mut runtime = loaded.policy::<M, O, K, N, P, 64, 64>().unwrap();
        runtime.reset(&[0.0, 0.1, 0.2]).unwrap();
        runtime.observe(&[0.1, 1.0, 0.5, 2.0]).unwrap();
        let chunk = *runtime.act(Noise::Rng(&mut Rng::new(9))).unwrap();
        assert!(chunk.positions.iter().flatten().all(|v| v.is_finite()));
        // Deterministic for a seed.
        let again = *runtime.act(Noise::Rng(&mut Rng::new(9))).unwrap();
        assert_eq!(chunk, again);
    }
}

#[test]
fn inconsistent_policy_is_refused_by_name() {
    let mut policy = sample_policy(6, 1);
    policy.hidden[1].shifts.pop();
    assert_eq!(
        policy.blob(),
        Err(BlobError::SectionLength(MlpSection::HiddenShifts(1).into()))
    );
    let mut policy = sample_policy(6, 1);
    policy.action_max.push(1.0);
    assert_eq!(
        policy.blob(),
        Err(BlobError::SectionLength(PolicySection::ActionNorm.into()))
    );
}
