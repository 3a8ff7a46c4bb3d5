//! The Cortex-M firmware (examples/cortex-m) decodes the same bytes as the host.
//!
//! The firmware's workload files are plain `core` + frmd-core code, compiled here for the host
//! as well. `qemu_digest_matches_host` builds the firmware, runs it on QEMU mps2-an386
//! (Cortex-M4F) and mps2-an500 (Cortex-M7) and requires the digest of all decoded outputs to equal
//! the host's. It needs `bash scripts/setup-cortex-m.sh` to have run (CI does that first); without
//! it, or with FRMD_SKIP_QEMU=1, it prints why and passes without checking.

#[allow(dead_code)]
#[path = "../../examples/cortex-m/src/digest.rs"]
mod digest;
#[path = "../../examples/cortex-m/src/shape.rs"]
mod shape;
#[allow(dead_code)] // REPEATS and NAME are firmware-only
#[path = "../../examples/cortex-m/src/workload.rs"]
mod workload;

use std::path::{Path, PathBuf};
use std::process::Command;

fn host_digest() -> u64 {
    let baked = workload::Baked::from_config(&shape::config()).expect("bake the policy decoder");
    let mut run = workload::Workload::new(&baked);
    let mut digest = digest::Fnv1a64::new();
    for case in 0..workload::CASES {
        run.prepare(case);
        run.run().expect("decode a fixed input");
        run.digest_outputs(&mut digest);
    }
    digest.finish()
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn fnv1a64_matches_published_vectors() {
    let hash = |bytes: &[u8]| {
        let mut digest = digest::Fnv1a64::new();
        digest.bytes(bytes);
        digest.finish()
    };
    assert_eq!(hash(b""), 0xcbf2_9ce4_8422_2325);
    assert_eq!(hash(b"a"), 0xaf63_dc4c_8601_ec8c);
    assert_eq!(hash(b"foobar"), 0x8594_4171_f739_67e8);
}

#[test]
fn firmware_inputs_are_distinct_and_in_range() {
    let first = workload::Inputs::fixed(0);
    let second = workload::Inputs::fixed(1);
    assert_ne!(first, second);
    assert_eq!(first, workload::Inputs::fixed(0));
    for case in 0..workload::CASES {
        let inputs = workload::Inputs::fixed(case);
        assert!(inputs.params.iter().flatten().all(|v| (-1.0..1.0).contains(v)));
        assert!(inputs.y0.iter().all(|v| (-0.5..0.5).contains(v)));
        assert!(inputs.v0.iter().all(|v| (-0.25..0.25).contains(v)));
    }
    assert_eq!(host_digest(), host_digest());
}

#[test]
fn qemu_digest_matches_host() {
    let root = repo_root();
    let env_file = std::env::var_os("FRMD_CORTEX_M_ENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/cortex-m.env"));
    let qemu_found = Command::new("qemu-system-arm").arg("--version").output().is_ok();
    if std::env::var_os("FRMD_SKIP_QEMU").is_some() || !env_file.exists() || !qemu_found {
        eprintln!(
            "qemu_digest_matches_host: SKIPPED (FRMD_SKIP_QEMU set, or no {} / qemu-system-arm: \
             run `bash scripts/setup-cortex-m.sh`)",
            env_file.display()
        );
        return;
    }
    let expected = format!("digest: {:016x}", host_digest());
    // The firmware's own target directory (as run-qemu.sh uses by default), so manual runs and
    // this test share one build; it is never the directory of the `cargo test` running this.
    let firmware_target = root.join("examples/cortex-m/target");
    for board in ["m4", "m7"] {
        let output = Command::new("bash")
            .arg(root.join("examples/cortex-m/run-qemu.sh"))
            .arg(board)
            .env("CARGO_TARGET_DIR", &firmware_target)
            .output()
            .expect("run examples/cortex-m/run-qemu.sh");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "run-qemu.sh {board} failed:\n{stdout}\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let digest_line = stdout.lines().find(|line| line.starts_with("digest: "));
        assert_eq!(
            digest_line,
            Some(expected.as_str()),
            "firmware on {board} decoded different bytes than the host:\n{stdout}"
        );
        eprintln!("{board}: {}", stdout.lines().collect::<Vec<_>>().join(" | "));
    }
}
