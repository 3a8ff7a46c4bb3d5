//! The DP settings training records in a checkpoint are what `FloatPolicy::load` samples with.
use crate::checkpoint::{self, CheckpointMeta, Role};
use crate::data::toy::{toy_config, toy_normalization};
use crate::diffusion::ddpm::{DpSampler, EpsParametrization};
use crate::models::HeadConfig;
use crate::models::OwnedNetwork;
use crate::policy::float::{dp_parametrization, FloatPolicy, Sampler, DP_TRAINING_KEY};
use crate::tasks::{Policy, PolicyInput};
use candle_core::Device;
use frmd_core::sigma::SigmaConfig;

/// A DP checkpoint records its noise-network parametrization and `load` samples with it:
/// the loaded policy reproduces the in-memory preconditioned policy, not the direct one.
/// Old checkpoints without the record load as `Direct`; a bad record is an error.
#[test]
fn dp_parametrization_is_saved_and_loaded() {
    let cfg = toy_config(HeadConfig::Raw);
    let net = OwnedNetwork::new_seeded(&cfg, 5, &Device::Cpu).unwrap();
    let norm = toy_normalization();
    let sampler = Sampler::Dp {
        sampler: DpSampler::Ddim,
        steps: 10,
    };
    let dir = std::env::temp_dir().join(format!("frmd-dp-param-{}", std::process::id()));
    let mut meta = CheckpointMeta::describe(Role::Dp, &cfg, SigmaConfig::default());
    meta.normalization = Some(norm.clone());
    meta.training = serde_json::json!({ DP_TRAINING_KEY: super::dp::DpConfig { parametrization: EpsParametrization::Preconditioned, eval_ema: 0.0 } });
    checkpoint::save(&dir, &meta, &net).unwrap();
    let obs = vec![vec![0.5f32]];
    let input = PolicyInput {
        obs_history: &obs,
        prev_action: &[15.0],
        prev_rate: &[1.0],
    };
    let chunk = |policy: &mut FloatPolicy| {
        policy.reset(3);
        policy.act(&input).unwrap()
    };
    let loaded = chunk(&mut FloatPolicy::load(&dir, None, None).unwrap());
    // The in-memory network as a policy with its default (direct) parametrization.
    let in_memory = || {
        let copy = net.duplicate(&Device::Cpu).unwrap();
        FloatPolicy::new(copy, norm.clone(), SigmaConfig::default(), sampler).unwrap()
    };
    let pre = chunk(&mut in_memory().with_dp_parametrization(EpsParametrization::Preconditioned));
    let direct = chunk(&mut in_memory());
    assert_eq!(loaded, pre);
    assert_ne!(loaded, direct);
    meta.training = serde_json::json!({ "steps": 1 });
    assert_eq!(
        dp_parametrization(&meta).unwrap(),
        EpsParametrization::Direct
    );
    meta.training = serde_json::json!({ DP_TRAINING_KEY: { "parametrization": "sideways" } });
    assert!(dp_parametrization(&meta).is_err());
    std::fs::remove_dir_all(&dir).ok();
}
