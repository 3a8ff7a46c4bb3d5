//! The exporter's blob round-trips through frmd-core's loader into a working policy.

use frmd_core::blob::{BlobError, LoadedMlp, SectionId};
use frmd_core::policy::Noise;
use frmd_core::rng::Rng;
use frmd_test_support::random_policy::*;

/// Copies into a 16-aligned buffer (a `Vec<u8>` has no alignment guarantee).
fn aligned(bytes: &[u8]) -> Vec<u128> {
    let mut words = vec![0_u128; bytes.len().div_ceil(16)];
    bytemuck::cast_slice_mut::<u128, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
    words
}

#[test]
fn written_blob_loads_and_matches_the_parts() {
    for steps in [1, 3] {
        let policy = sample_policy(5, steps);
        let blob = frmd_export::blob::write(&policy).unwrap();
        let words = aligned(&blob);
        let bytes = &bytemuck::cast_slice::<u128, u8>(&words)[..blob.len()];
        let loaded = LoadedMlp::load(bytes).unwrap();
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
        frmd_export::blob::write(&policy),
        Err(BlobError::SectionLength(SectionId::HiddenShifts(1)))
    );
    let mut policy = sample_policy(6, 1);
    policy.action_max.push(1.0);
    assert_eq!(
        frmd_export::blob::write(&policy),
        Err(BlobError::SectionLength(SectionId::ActionNorm))
    );
}
