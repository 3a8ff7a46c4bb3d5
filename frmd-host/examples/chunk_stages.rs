//! Instruction counts per stage of one chunk (`frmd_host::bench::stages`) under callgrind:
//! `chunk_stages PRECISION BACKBONE REPS` (int8 | int16, e.g. `mlp`, `mlp-paper`) runs every stage
//! of the randomly initialized reach-shape student once untimed, then `REPS` times inside
//! `measured`; `scripts/host-stages.sh` runs it with
//! `valgrind --tool=callgrind --collect-atstart=no --toggle-collect=chunk_stages::measured
//! --dump-after=chunk_stages::measured`, so that dump `i` holds stage `i`'s instructions alone.
//! Prints the stage names in dump order. Natively it prints the stages' median wall times.
use frmd_host::bench::fixtures::{reach_input, reach_student};
use frmd_host::bench::stages::{stage_times, with_stages, Stages};
use frmd_host::tasks::PolicyInput;

/// The stage's repetitions (callgrind collects inside this function only).
#[inline(never)]
fn measured(stages: &mut dyn Stages, index: usize, reps: usize) -> anyhow::Result<()> {
    for _ in 0..reps {
        stages.run(index)?;
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let precision = args.get(1).map(String::as_str).unwrap_or("int8");
    let backbone = args.get(2).map(String::as_str).unwrap_or("mlp");
    let reps: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(20);
    let timed = args.get(4).is_some_and(|s| s == "--time");
    let dir = std::env::temp_dir().join(format!("frmd-stages-{}", std::process::id()));
    let policies = reach_student(&dir, &backbone.parse()?, 1);
    let _ = std::fs::remove_dir_all(&dir);
    let core = policies?.core.map_err(anyhow::Error::msg)?;
    let (mut policy, blob) = match precision {
        "int8" => (core.int8, core.int8_blob),
        "int16" => (core.int16, core.int16_blob),
        other => anyhow::bail!("unknown precision {other}"),
    };
    let (history, prev, rate) = reach_input();
    let input = PolicyInput {
        obs_history: &history,
        prev_action: &prev,
        prev_rate: &rate,
    };
    with_stages(&blob, &mut policy, &input, |stages| {
        stages.check()?;
        if timed {
            for (name, ns) in stage_times(stages, reps)? {
                println!("{name}\t{ns:.0}");
            }
            return Ok(());
        }
        for (index, name) in stages.names().iter().enumerate() {
            stages.run(index)?;
            measured(stages, index, reps)?;
            println!("{name}");
        }
        Ok(())
    })
}
