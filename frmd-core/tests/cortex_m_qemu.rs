//! The Cortex-M firmware (examples/cortex-m) computes the same bytes as the host.
//!
//! The firmware's workloads are plain `core` + frmd-core code in `frmd-firmware-support`
//! (`examples/cortex-m/support`, whose synthetic MLP generator its build.rs runs), so they run
//! here on the host as well.
//! `qemu_digests_match_host` builds the firmware images, runs them on every QEMU board of
//! `run-qemu.sh` (Cortex-M4F, M7, M33, M0, M55) and requires each printed digest to equal the
//! host's: ProDMP decode (f32), int8 MLP + decode and the fully connected kernels on random
//! shapes (int8 activations, and int16 activations with int64 accumulation) are bit-identical on
//! x86-64 and on every core, DSP kernels or portable, FPU or soft float. It needs
//! `bash scripts/setup-cortex-m.sh` to have run (CI does that first); without it, or with
//! FRMD_SKIP_QEMU=1, it prints why and passes without checking
//! (unless FRMD_REQUIRE_QEMU is set, as in CI: then it fails).

use frmd_firmware_support::host::qemu;
use frmd_firmware_support::synthetic::mlp as synthetic_mlp;
use frmd_firmware_support::{kernel_workload, mlp_workload, prodmp_workload, shape, workload};

fn baked() -> prodmp_workload::Baked {
    prodmp_workload::Baked::from_config(&shape::config()).expect("bake the policy decoder")
}

fn prodmp_digest() -> u64 {
    let baked = baked();
    let mut workload = prodmp_workload::ProDmpWorkload::new(&baked);
    workload::digest_all(&mut workload).expect("decode the fixed inputs")
}

fn mlp_digest() -> u64 {
    let baked = baked();
    let model = synthetic_mlp::generate();
    let hidden = model.hidden_layers();
    let mut workload = mlp_workload::MlpWorkload::new(model.mlp(&hidden), &baked);
    workload::digest_all(&mut workload).expect("run the synthetic policy on the fixed inputs")
}

fn kernels_digest() -> u64 {
    let mut workload = kernel_workload::KernelWorkload::new();
    workload::digest_all(&mut workload).expect("run the kernel cases")
}

/// The host side of the kernel cases is itself the same on the portable and (where the CPU has
/// it) the AVX2 path, and the cases reach what they are meant to: inputs wider than the pair
/// buffer, every width remainder, odd row counts, int16 inputs.
#[test]
fn kernel_cases_agree_on_the_host_paths() {
    let with_avx2 = kernels_digest();
    #[cfg(target_arch = "x86_64")]
    {
        frmd_core::kernels::x86::set_avx2_enabled(false);
        let portable = kernels_digest();
        frmd_core::kernels::x86::set_avx2_enabled(true);
        assert_eq!(portable, with_avx2);
    }
    let mut workload = kernel_workload::KernelWorkload::new();
    let mut widths = Vec::new();
    for case in 0..kernel_workload::INT8_CASES {
        use frmd_firmware_support::workload::Workload;
        workload.prepare(case).unwrap();
        widths.push((workload.width(), workload.rows()));
    }
    assert!(widths.iter().any(|(w, _)| *w > 256));
    for remainder in 0..8 {
        assert!(
            widths.iter().any(|(w, _)| w % 8 == remainder),
            "no width = {remainder} mod 8"
        );
    }
    for steps in 0..4 {
        assert!(
            widths.iter().any(|(w, _)| (w / 8) % 4 == steps && *w >= 8),
            "no width with {steps} steps mod 4"
        );
    }
    assert!(widths.iter().any(|(_, r)| r % 2 == 1) && widths.iter().any(|(_, r)| r % 2 == 0));
}

/// The int8 cases alone give the digest the workload had before the int16 cases were added: the
/// generic kernels left every int8 bit where it was.
#[test]
fn int8_kernel_cases_keep_their_digest() {
    use frmd_firmware_support::workload::Workload;
    let mut workload = kernel_workload::KernelWorkload::new();
    let mut digest = frmd_core::hash::Fnv1a64::new();
    for case in 0..kernel_workload::INT8_CASES {
        workload.prepare(case).unwrap();
        workload.run().unwrap();
        workload.digest_outputs(&mut digest);
    }
    assert_eq!(digest.finish(), kernel_workload::INT8_DIGEST);
}

/// The int16-activation cases equal frmd-core's wide-integer model on the host (and the QEMU
/// test shows every core computes the host's bytes), and they reach what they are meant to:
/// the pair buffer (<= 256 columns), in-loop int16 unpacking (257..=512), several 512-column
/// chunks, every width remainder mod 8 and step count mod 4 on aligned rows, a second 16-row
/// block, wrapped chunk sums, clamped and unclamped outputs.
#[test]
fn int16_kernel_cases_match_the_wide_model() {
    use frmd_firmware_support::workload::Workload;
    let mut workload = kernel_workload::KernelWorkload::new();
    let mut shapes = Vec::new();
    let (mut wrapped, mut unclamped, mut clamped) = (0, 0, 0);
    for case in kernel_workload::INT8_CASES..kernel_workload::CASES {
        workload.prepare(case).unwrap();
        workload.run().unwrap();
        let coverage = workload
            .int16_against_model()
            .unwrap_or_else(|e| panic!("case {case}: {e}"));
        wrapped += coverage.wrapped_rows;
        unclamped += coverage.unclamped;
        clamped += coverage.clamped;
        shapes.push((workload.width(), workload.rows(), workload.aligned()));
    }
    let aligned: Vec<(usize, usize)> = shapes
        .iter()
        .filter(|(_, _, a)| *a)
        .map(|(w, r, _)| (*w, *r))
        .collect();
    assert!(aligned.iter().any(|(w, _)| *w <= 256 && w % 8 == 0));
    assert!(aligned
        .iter()
        .any(|(w, _)| (257..=512).contains(w) && w % 4 == 0));
    assert!(aligned.iter().any(|(w, _)| *w > 1024 && w % 4 == 0));
    for remainder in 0..8 {
        assert!(
            shapes.iter().any(|(w, _, _)| w % 8 == remainder),
            "no int16 width = {remainder} mod 8"
        );
    }
    for steps in 0..4 {
        assert!(
            aligned
                .iter()
                .any(|(w, _)| (w / 8) % 4 == steps && w % 4 == 0),
            "no aligned int16 width with {steps} steps mod 4"
        );
    }
    assert!(shapes.iter().any(|(_, r, _)| *r > 16));
    assert!(shapes.iter().any(|(_, _, a)| !*a));
    assert!(wrapped > 0, "no wrapped chunk sum");
    assert!(
        unclamped > 100 && clamped > 20,
        "{unclamped} unclamped, {clamped} clamped"
    );
    eprintln!(
        "int16 cases: {wrapped} wrapped rows, {unclamped} unclamped, {clamped} clamped outputs"
    );
}

#[test]
fn firmware_inputs_are_distinct_and_in_range() {
    let first = prodmp_workload::Inputs::fixed(0);
    assert_ne!(first, prodmp_workload::Inputs::fixed(1));
    assert_eq!(first, prodmp_workload::Inputs::fixed(0));
    for case in 0..prodmp_workload::CASES {
        let inputs = prodmp_workload::Inputs::fixed(case);
        assert!(inputs
            .params
            .iter()
            .flatten()
            .all(|v| (-1.0..1.0).contains(v)));
        assert!(inputs.y0.iter().all(|v| (-0.5..0.5).contains(v)));
        assert!(inputs.v0.iter().all(|v| (-0.25..0.25).contains(v)));
    }
    assert_eq!(prodmp_digest(), prodmp_digest());
}

#[test]
fn synthetic_mlp_is_deterministic_and_valid() {
    let model = synthetic_mlp::generate();
    let hidden = model.hidden_layers();
    let mlp = model.mlp(&hidden);
    mlp.validate(shape::MLP_WIDTH)
        .expect("valid synthetic network");
    assert_eq!(mlp.input_width(), shape::MLP_INPUT);
    assert_eq!(mlp.output_width(), shape::MLP_OUTPUT);
    assert_eq!(
        model.weight_bytes(),
        synthetic_mlp::generate().weight_bytes()
    );
    // The network is not degenerate: its outputs vary with the observation.
    let mut out_a = [0.0_f32; shape::MLP_OUTPUT];
    let mut out_b = [0.0_f32; shape::MLP_OUTPUT];
    let mut scratch = frmd_core::model::mlp::Int8Scratch::<{ shape::MLP_WIDTH }>::new();
    mlp.forward(&[0.5; shape::MLP_INPUT], &mut out_a, &mut scratch)
        .expect("forward");
    mlp.forward(&[-0.5; shape::MLP_INPUT], &mut out_b, &mut scratch)
        .expect("forward");
    assert_ne!(out_a, out_b);
    assert!(out_a.iter().chain(&out_b).all(|v| v.is_finite()));
    assert_eq!(mlp_digest(), mlp_digest());
}

#[test]
fn qemu_digests_match_host() {
    let root = qemu::repo_root();
    if !qemu::available("qemu_digests_match_host", &root) {
        return;
    }
    let images = [
        ("prodmp", prodmp_digest()),
        ("mlp", mlp_digest()),
        ("kernels", kernels_digest()),
    ];
    for (firmware, host_digest) in images {
        qemu::assert_digest_on(&root, &qemu::BOARDS, firmware, host_digest, "the host");
    }
}
