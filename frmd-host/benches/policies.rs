//! Criterion benches of one action chunk (batch 1) for every policy kind `frmd bench` compares,
//! on randomly initialized networks of the quickstart backbone (latency does not depend on the
//! weights): candle student (1 step), teacher (10 Heun steps), DP (100 DDPM and 10 DDIM steps).
//! The frmd-core int8 and f32 one-step paths of the same backbone are in `benches/chunk.rs`;
//! `frmd bench` prints all of them in one table with ratios.
//!
//! Run with `RAYON_NUM_THREADS=1 cargo bench -p frmd-host --bench policies --bench chunk`.
use criterion::{criterion_group, criterion_main, Criterion};
use frmd_host::bench::fixtures::synthetic_float_policy;
use frmd_host::bench::{BenchConfig, FixedInput};
use frmd_host::checkpoint::Role;
use frmd_host::diffusion::samplers::Solver;
use frmd_host::tasks::Policy;

/// The `reach` observation size.
const OBS_DIM: usize = 6;

fn chunk_latency(c: &mut Criterion) {
    let cases = [
        ("candle student-1", Role::Student, 1, None),
        (
            "candle teacher-heun-10",
            Role::Teacher,
            10,
            Some(Solver::Heun),
        ),
        ("candle dp-ddpm-100", Role::Dp, 100, None),
        ("candle dp-ddim-10", Role::Dp, 10, None),
    ];
    // The quickstart backbone, as `frmd bench` times it.
    let backbone = BenchConfig::default().backbone;
    let mut group = c.benchmark_group("chunk");
    for (name, role, steps, solver) in cases {
        let mut policy = match synthetic_float_policy(&backbone, OBS_DIM, role, Some(steps), solver)
        {
            Ok(p) => p,
            Err(e) => panic!("building {name}: {e:#}"),
        };
        let (obs_dim, action_dim, history) = policy.input_sizes();
        let fixed = FixedInput::new(obs_dim, action_dim, history);
        policy.reset(0);
        group.bench_function(name, |b| {
            b.iter(|| {
                policy
                    .act(&fixed.input())
                    .map(|chunk| chunk.len())
                    .unwrap_or(0)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, chunk_latency);
criterion_main!(benches);
