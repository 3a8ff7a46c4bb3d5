//! Instruction counts per chunk under callgrind: runs `CHUNKS` (argument 2, default 1) int8 or
//! float chunks (argument 1: int8 | int8-avx2 | int8-portable | int16 | core-f32 | candle-f32;
//! int16: the student exported with int16 activations) of a
//! randomly initialized student at the reach shape with backbone argument 3 (default `mlp`;
//! `transformer-lite` runs frmd-core's transformer policy). Per-chunk Ir = (Ir(101 chunks) -
//! Ir(1 chunk)) / 100. `int8-avx2` / `int8-portable` run the int8 policy with frmd-core's AVX-512 and
//! AVX-VNNI / AVX2 kernels turned off (x86-64; callgrind's virtual CPU reports neither VNNI kind
//! anyway).
use frmd_host::bench::fixtures::{reach_input, reach_student};
use frmd_host::tasks::{Policy, PolicyInput};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("int8");
    let chunks: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let backbone = args.get(3).map(String::as_str).unwrap_or("mlp");
    let dir = std::env::temp_dir().join(format!("frmd-icount-{}", std::process::id()));
    let mut p = reach_student(&dir, &backbone.parse()?, 1)?;
    let flash = p.core.as_ref().map_or(0, |core| core.flash_bytes);
    #[cfg(target_arch = "x86_64")]
    match which {
        "int8-portable" => drop(frmd_core::kernels::x86::set_avx2_enabled(false)),
        "int8-avx2" => {
            frmd_core::kernels::x86::set_avx512_enabled(false);
            frmd_core::kernels::x86::set_avx_vnni_enabled(false);
        }
        _ => {}
    }
    let which_policy = if which.starts_with("int8") {
        "int8"
    } else {
        which
    };
    let policy: &mut dyn Policy = match (which_policy, &mut p.core) {
        ("candle-f32", _) => &mut p.float,
        ("int8", Ok(core)) => &mut core.int8,
        ("int16", Ok(core)) => &mut core.int16,
        ("core-f32", Ok(core)) => &mut core.core_f32,
        ("int8" | "int16" | "core-f32", Err(reason)) => {
            anyhow::bail!("no frmd-core policy for {backbone}: {reason}")
        }
        (other, _) => anyhow::bail!("unknown policy {other}"),
    };
    let (history, prev, rate) = reach_input();
    let input = PolicyInput {
        obs_history: &history,
        prev_action: &prev,
        prev_rate: &rate,
    };
    policy.reset(7);
    let mut checksum = 0f32;
    for _ in 0..chunks {
        checksum += policy.act(&input)?[0][0];
    }
    println!("{which} {backbone}: {chunks} chunks, checksum {checksum}, int8 flash {flash} B");
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
