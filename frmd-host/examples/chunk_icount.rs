//! Instruction counts per chunk under callgrind: runs `CHUNKS` (argument 2, default 1) int8 or
//! float chunks (argument 1: int8 | core-f32 | candle-f32) of the MLP-256 reach-shape student.
//! Per-chunk Ir = (Ir(101 chunks) - Ir(1 chunk)) / 100.
use frmd_host::bench::{reach_input, reach_student};
use frmd_host::eval::policy::{Policy, PolicyInput};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("int8");
    let chunks: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let backbone = args.get(3).map(String::as_str).unwrap_or("mlp");
    let dir = std::env::temp_dir().join(format!("frmd-icount-{}", std::process::id()));
    let mut p = reach_student(&dir, backbone, 1)?;
    let flash = p.core.as_ref().map(|c| c.flash_bytes).unwrap_or(0);
    let policy: &mut dyn Policy = match (which, &mut p.core) {
        ("candle-f32", _) => &mut p.float,
        ("int8", Ok(core)) => &mut core.int8,
        ("core-f32", Ok(core)) => &mut core.core_f32,
        ("int8" | "core-f32", Err(reason)) => anyhow::bail!("no frmd-core policy for {backbone}: {reason}"),
        (other, _) => anyhow::bail!("unknown policy {other}"),
    };
    let (history, prev, rate) = reach_input();
    let input = PolicyInput { obs_history: &history, prev_action: &prev, prev_rate: &rate };
    policy.reset(7);
    let mut checksum = 0f32;
    for _ in 0..chunks {
        checksum += policy.act(&input)?[0][0];
    }
    println!("{which} {backbone}: {chunks} chunks, checksum {checksum}, int8 flash {flash} B");
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
