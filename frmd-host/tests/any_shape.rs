//! The host runs any exported shape from its blob, without a code change: a MetaWorld-sized MLP
//! policy (history 2, 39-dim observation, 4-dim action, horizon 12, 21 ProDMP parameters per DoF;
//! synthetic weights) and a small one, each exported as a blob, loaded and run through the
//! evaluation policy interface, with the chunk frmd-core's own policy computes.

use frmd_core::blob::{AlignedBlob, LoadedMlp};
use frmd_core::policy::{Noise, PolicyDims};
use frmd_core::rng::Rng;
use frmd_host::policy::int8::Int8Policy;
use frmd_host::tasks::{Policy, PolicyInput};
use frmd_test_support::random_policy::{random_policy, Dims};

fn run_shape(dims: Dims) {
    let policy = random_policy(7, 2, &dims);
    let blob = policy.blob().unwrap();
    let mut host = Int8Policy::from_blob(&blob, "int8").unwrap();
    let expected = PolicyDims {
        history: dims.m,
        obs_dim: dims.o,
        action_dim: dims.k,
        horizon: dims.n,
        params_per_dof: dims.p,
    };
    assert_eq!(host.dims(), expected);
    assert_eq!(host.history(), dims.m);
    let mut rng = Rng::new(3);
    let history: Vec<Vec<f32>> = (0..dims.m)
        .map(|_| (0..dims.o).map(|_| rng.uniform() - 0.5).collect())
        .collect();
    let prev_action: Vec<f32> = (0..dims.k).map(|_| 0.2 * rng.uniform()).collect();
    let prev_rate = vec![0.1; dims.k];
    let input = PolicyInput {
        obs_history: &history,
        prev_action: &prev_action,
        prev_rate: &prev_rate,
    };
    let noise: Vec<f32> = (0..2 * dims.n * dims.k).map(|_| rng.gaussian()).collect();
    let chunk = host.run_with_noise(&input, &noise).unwrap();
    assert_eq!(chunk.len(), dims.n);
    assert!(chunk
        .iter()
        .all(|row| row.len() == dims.k && row.iter().all(|v| v.is_finite())));

    // The same chunk from frmd-core's policy over the loaded blob, with capacities of exactly
    // this shape for the MetaWorld case.
    let aligned = AlignedBlob::new(&blob);
    let loaded = LoadedMlp::load(aligned.bytes()).unwrap();
    if (dims.m, dims.o, dims.k, dims.n, dims.p) == (2, 39, 4, 12, 21) {
        let mut exact = loaded.policy::<2, 39, 4, 12, 21, 134, 134>().unwrap();
        exact.reset(&prev_action).unwrap();
        for obs in &history {
            exact.observe(obs).unwrap();
        }
        exact.set_previous_action(&prev_action, &prev_rate).unwrap();
        let reference = exact.act(Noise::Given(&noise)).unwrap();
        let rows: Vec<Vec<f32>> = reference.positions.iter().map(|row| row.to_vec()).collect();
        assert_eq!(
            chunk, rows,
            "host capacities give the chunk of the exact-size policy"
        );
    }

    // Closed-loop use through the evaluation interface: seeded noise, repeatable.
    host.reset(11);
    let first = host.act(&input).unwrap();
    host.reset(11);
    assert_eq!(host.act(&input).unwrap(), first);
}

#[test]
fn metaworld_shape_loads_and_runs_from_a_blob() {
    run_shape(Dims::new((2, 39, 4, 12, 21), vec![64, 64]));
}

#[test]
fn other_shapes_load_and_run_from_a_blob() {
    run_shape(Dims::new((3, 5, 3, 8, 5), vec![24, 20]));
    run_shape(Dims::new((1, 20, 7, 16, 11), vec![48]));
}
