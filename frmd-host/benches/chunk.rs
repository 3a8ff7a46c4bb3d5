//! One-step chunk latency, all in one run: frmd-core int8 policy vs the candle float student
//! (same MLP-256 model, random weights), plus frmd-core's f32 twin. Batch 1, RAYON_NUM_THREADS
//! should be 1.
use criterion::{criterion_group, criterion_main, Criterion};
use frmd_host::bench::{reach_input, reach_student};
use frmd_host::eval::policy::{Policy, PolicyInput};

fn chunk(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("frmd-bench-chunk-{}", std::process::id()));
    let mut p = reach_student(&dir, "mlp", 1).expect("bench student");
    let (history, prev, rate) = reach_input();
    let input = PolicyInput { obs_history: &history, prev_action: &prev, prev_rate: &rate };
    let mut group = c.benchmark_group("one-step chunk, MLP-256, reach shape");
    let policies: [(&str, &mut dyn Policy); 3] = [("candle-f32", &mut p.float), ("core-f32", &mut p.core_f32), ("core-int8", &mut p.int8)];
    for (name, policy) in policies {
        policy.reset(7);
        group.bench_function(name, |b| b.iter(|| policy.act(&input).expect("act")));
    }
    group.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, chunk);
criterion_main!(benches);
