//! Host timing of the int8 policy from a blob at firmware-like size (ignored: a measurement, not a
//! check). `cargo test -p frmd-export --release --test timing -- --ignored --nocapture`.

use std::time::Instant;

use frmd_core::blob::LoadedMlp;
use frmd_core::policy::Noise;
use frmd_core::rng::Rng;
use frmd_test_support::random_policy::{random_policy, Dims};

const M: usize = 2;
const O: usize = 10;
const K: usize = 3;
const N: usize = 12;
const P: usize = 21;

#[test]
#[ignore]
fn int8_policy_act_time_on_host() {
    for steps in [1, 2, 4] {
        let dims = Dims::new((M, O, K, N, P), vec![256, 256, 256]);
        let policy = random_policy(3, steps, &dims);
        let blob = frmd_core::blob::AlignedBlob::new(&policy.blob().unwrap());
        let bytes = blob.bytes();
        let loaded = LoadedMlp::load(bytes).unwrap();
        let mut runtime = loaded.policy::<M, O, K, N, P, 64, 256>().unwrap();
        runtime.reset(&[0.0; K]).unwrap();
        runtime.observe(&[0.1; O]).unwrap();
        let mut rng = Rng::new(1);
        let iterations = 300;
        let start = Instant::now();
        for _ in 0..iterations {
            runtime.act(Noise::Rng(&mut rng)).unwrap();
        }
        let per_act = start.elapsed().as_secs_f64() / f64::from(iterations) * 1e6;
        let memory = policy.memory();
        println!(
            "{steps} step(s), MLP {}-256-256-256-{}: {per_act:.1} us per chunk on this host; blob {} B, flash {} B, scratch {} B",
            policy.input_width().unwrap(),
            K * P,
            bytes.len(),
            memory.flash_bytes(),
            memory.scratch_bytes
        );
    }
}
