//! Digests of what a host computes, one `name digest` line each: the Cortex-M firmware's
//! workloads (`frmd-firmware-support`: ProDMP decode, the firmware-size int8 MLP with its decode,
//! the fully connected kernel cases with int8 and int16 activations) and chunks of the sample
//! policy blob (loader, sampler with the integer Gaussian, decode; its weights packed where the
//! CPU runs packed kernels). The same bytes on every host: on x86-64 every kernel level this CPU
//! runs (portable, AVX2, AVX-VNNI, AVX-512 VNNI, packed weights or row-major) is checked to agree
//! before printing, on aarch64 every level (portable, NEON, NEON with `SDOT`) likewise;
//! `scripts/aarch64.sh` runs this example natively and under
//! `qemu-aarch64` and compares the lines.
//!
//! `frmd-host-digests mlp N` runs the MLP workload's first case `N` times instead (for instruction
//! counts per chunk: the difference of two `N` divided by their difference); on aarch64,
//! `FRMD_KERNELS=portable|neon|sdot` picks its row kernels.
//!
//! Run with `cargo run --release --manifest-path examples/host-digests/Cargo.toml`.
use frmd_core::blob::LoadedMlp;
use frmd_core::hash::Fnv1a64;
use frmd_core::policy::{AlignedBytes, Noise, Policy};
use frmd_core::rng::Rng;
use frmd_firmware_support::synthetic::mlp as synthetic_mlp;
use frmd_firmware_support::workload::{digest_all, Workload};
use frmd_firmware_support::{kernel_workload, mlp_workload, prodmp_workload, shape};

macro_rules! sample {
    () => {
        include_bytes!(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../frmd-core/tests/data/sample_policy.blob"
        ))
    };
}
static BLOB: AlignedBytes<{ sample!().len() }> = AlignedBytes(*sample!());

fn baked() -> prodmp_workload::Baked {
    prodmp_workload::Baked::from_config(&shape::config()).expect("bake the policy decoder")
}

/// 50 chunks of the sample policy from fresh episodes with varying observations.
fn policy_digest() -> u64 {
    let loaded = LoadedMlp::load(&BLOB.0).expect("sample blob");
    // The weights packed for this CPU's kernels where it runs them (same bits as row-major).
    let mut packed = Vec::new();
    if frmd_core::kernels::packed::runs_here() {
        let network = loaded.network::<40>().expect("network");
        packed.resize(network.packed_len(), 0);
        network.pack_weights(&mut packed).expect("pack");
    }
    let mut network = loaded.network::<40>().expect("network");
    network.use_packed_weights(&packed).expect("packed weights");
    let mut policy = Policy::<_, 2, 3, 2, 6, 4, 32>::new(loaded.config(), network).expect("policy");
    let mut rng = Rng::new(7);
    let mut digest = Fnv1a64::new();
    for chunk in 0..50 {
        let x = chunk as f32 / 50.0 - 0.5;
        policy.reset(&[x, -x]).expect("reset");
        policy.observe(&[x, 0.3 * x, -0.2]).expect("observe");
        policy.observe(&[0.5 * x, x, 0.1]).expect("observe");
        let trajectory = policy.act(Noise::Rng(&mut rng)).expect("act");
        digest.f32s(trajectory.positions.as_flattened());
        digest.f32s(trajectory.velocities.as_flattened());
    }
    digest.finish()
}

fn digests() -> Vec<(&'static str, u64)> {
    let baked = baked();
    let model = synthetic_mlp::generate();
    let hidden = model.hidden_layers();
    let mut mlp = mlp_workload::MlpWorkload::new(model.mlp(&hidden), &baked);
    let mut prodmp = prodmp_workload::ProDmpWorkload::new(&baked);
    let mut kernels = kernel_workload::KernelWorkload::new();
    vec![
        ("prodmp", digest_all(&mut prodmp).expect("decode")),
        ("mlp", digest_all(&mut mlp).expect("mlp")),
        ("kernels", digest_all(&mut kernels).expect("kernels")),
        ("policy", policy_digest()),
    ]
}

/// The digests at every kernel level of this CPU, which must agree.
#[cfg(target_arch = "x86_64")]
fn checked_digests() -> Vec<(&'static str, u64)> {
    use frmd_core::kernels::x86;
    let best = digests();
    let (avx512, vnni, packed) = (
        x86::avx512_active(),
        x86::avx_vnni_active(),
        x86::packed_active(),
    );
    for (level, wide, dot, pack, avx2) in [
        ("row-major", avx512, vnni, false, true),
        ("avx-vnni", false, vnni, packed, true),
        ("avx2", false, false, false, true),
        ("portable", false, false, false, false),
    ] {
        x86::set_avx512_enabled(wide);
        x86::set_avx_vnni_enabled(dot);
        x86::set_packed_enabled(pack);
        x86::set_avx2_enabled(avx2);
        assert_eq!(digests(), best, "the {level} kernels differ");
    }
    x86::set_avx2_enabled(true);
    x86::set_avx_vnni_enabled(vnni);
    x86::set_avx512_enabled(avx512);
    x86::set_packed_enabled(packed);
    best
}

/// The digests at every kernel level of this CPU (NEON with `SDOT` if it has it, NEON without,
/// portable), which must agree.
#[cfg(target_arch = "aarch64")]
fn checked_digests() -> Vec<(&'static str, u64)> {
    use frmd_core::kernels::aarch64;
    let best = digests();
    let dotprod = aarch64::dotprod_active();
    for (level, neon, sdot) in [("neon", true, false), ("portable", false, false)] {
        aarch64::set_neon_enabled(neon);
        aarch64::set_dotprod_enabled(sdot);
        assert_eq!(digests(), best, "the {level} kernels differ");
    }
    aarch64::set_neon_enabled(true);
    aarch64::set_dotprod_enabled(dotprod);
    best
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn checked_digests() -> Vec<(&'static str, u64)> {
    digests()
}

/// `FRMD_KERNELS=portable|neon|sdot` (aarch64) picks the row kernels of the `mlp N` runs.
#[cfg(target_arch = "aarch64")]
fn select_kernels() {
    use frmd_core::kernels::aarch64;
    match std::env::var("FRMD_KERNELS").as_deref() {
        Ok("portable") => {
            aarch64::set_neon_enabled(false);
        }
        Ok("neon") => {
            aarch64::set_dotprod_enabled(false);
        }
        Ok("sdot") => assert!(aarch64::set_dotprod_enabled(true), "this CPU has no SDOT"),
        Ok(other) => panic!("FRMD_KERNELS: expected portable, neon or sdot, got {other}"),
        Err(_) => {}
    }
}

#[cfg(not(target_arch = "aarch64"))]
fn select_kernels() {}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("mlp") {
        let runs: usize = args.get(2).and_then(|n| n.parse().ok()).unwrap_or(1);
        select_kernels();
        let baked = baked();
        let model = synthetic_mlp::generate();
        let hidden = model.hidden_layers();
        let mut mlp = mlp_workload::MlpWorkload::new(model.mlp(&hidden), &baked);
        mlp.prepare(0).expect("prepare");
        let mut digest = Fnv1a64::new();
        for _ in 0..runs {
            mlp.run().expect("run");
        }
        mlp.digest_outputs(&mut digest);
        println!("mlp x{runs} {:016x}", digest.finish());
        return;
    }
    for (name, digest) in checked_digests() {
        println!("{name} {digest:016x}");
    }
}
