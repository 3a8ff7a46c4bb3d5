//! One-step chunk latency, all in one run: frmd-core int8 policy vs the candle float student
//! (same MLP-256 model, random weights), plus frmd-core's f32 twin. Batch 1, RAYON_NUM_THREADS
//! should be 1. On x86-64 with AVX2 also the int8 policy with the portable kernels.
use criterion::{criterion_group, criterion_main, Criterion};
use frmd_host::bench::fixtures::{reach_input, reach_student};
use frmd_host::tasks::{Policy, PolicyInput};

fn chunk(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("frmd-bench-chunk-{}", std::process::id()));
    let (history, prev, rate) = reach_input();
    let input = PolicyInput {
        obs_history: &history,
        prev_action: &prev,
        prev_rate: &rate,
    };
    for backbone in ["mlp", "transformer-lite"] {
        let mut p =
            reach_student(&dir, &backbone.parse().expect("a backbone"), 1).expect("bench student");
        let mut group = c.benchmark_group(format!("one-step chunk, {backbone}, reach shape"));
        let mut policies: Vec<(&str, &mut dyn Policy)> = vec![("candle-f32", &mut p.float)];
        match &mut p.core {
            Ok(core) => {
                policies.push(("core-f32", &mut core.core_f32));
                policies.push(("core-int8", &mut core.int8));
            }
            Err(reason) => eprintln!("{backbone}: no frmd-core policy ({reason})"),
        }
        for (name, policy) in policies {
            policy.reset(7);
            group.bench_function(name, |b| b.iter(|| policy.act(&input).expect("act")));
        }
        // The int8 policy with frmd-core's portable kernels (what CPUs without AVX2 run).
        #[cfg(target_arch = "x86_64")]
        if let (Ok(core), true) = (&mut p.core, frmd_core::kernels::x86::avx2_active()) {
            frmd_core::kernels::x86::set_avx2_enabled(false);
            core.int8.reset(7);
            group.bench_function("core-int8-portable", |b| {
                b.iter(|| core.int8.act(&input).expect("act"))
            });
            frmd_core::kernels::x86::set_avx2_enabled(true);
        }
        group.finish();
    }
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, chunk);
criterion_main!(benches);
