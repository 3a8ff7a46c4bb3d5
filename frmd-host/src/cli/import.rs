//! `frmd import`: demonstrations from other formats as an FRMD dataset
//! ([`crate::data::lerobot::import`] for LeRobot's).
use crate::data::lerobot::{import, ImportConfig};
use crate::data::ActionBeforeStart;
use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Subcommand, Debug)]
pub enum ImportCommand {
    /// A LeRobot dataset directory (LeRobotDataset v2.0, v2.1 or v3.0: meta/info.json and the
    /// parquet files of data/; images and videos are not read).
    Lerobot(LerobotArgs),
}

#[derive(Args, Debug)]
pub struct LerobotArgs {
    /// The dataset directory (holding meta/ and data/).
    pub dir: PathBuf,
    /// Output safetensors file (must not exist unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing --out file.
    #[arg(long)]
    pub force: bool,
    /// Column that becomes the observation.
    #[arg(long, default_value_t = ImportConfig::default().state_key)]
    pub state_key: String,
    /// Column that becomes the action.
    #[arg(long, default_value_t = ImportConfig::default().action_key)]
    pub action_key: String,
    /// FRMD task name recorded in the dataset (default: the directory's name).
    #[arg(long)]
    pub task: Option<String>,
    /// The command before each episode's first step: first (position targets, the default) or
    /// zero (velocity or displacement commands).
    #[arg(long, default_value = "first", value_parser = ActionBeforeStart::parse)]
    pub action_before_start: ActionBeforeStart,
    /// Largest allowed difference between a timestamp step and 1 / fps, seconds.
    #[arg(long, default_value_t = ImportConfig::default().fps_tolerance)]
    pub fps_tolerance: f64,
}

pub fn run(cmd: ImportCommand) -> anyhow::Result<ExitCode> {
    let ImportCommand::Lerobot(args) = cmd;
    frmd_formats::artifact::check_output_file(&args.out, "--out", args.force, &[])?;
    anyhow::ensure!(
        args.fps_tolerance.is_finite() && args.fps_tolerance >= 0.0,
        "--fps-tolerance {}: expected seconds >= 0",
        args.fps_tolerance
    );
    let cfg = ImportConfig {
        state_key: args.state_key,
        action_key: args.action_key,
        task: args.task,
        action_before_start: args.action_before_start,
        fps_tolerance: args.fps_tolerance,
    };
    let imported = import(&args.dir, &cfg)?;
    imported.dataset.save(&args.out)?;
    let d = &imported.dataset;
    println!(
        "wrote {}: LeRobot {} ({} data file{}), {} episodes, {} steps, obs_dim {} (`{}`), action_dim {} \
         (`{}`), fps {}, task {:?}",
        args.out.display(),
        imported.version,
        imported.files,
        if imported.files == 1 { "" } else { "s" },
        d.num_episodes(),
        d.len(),
        d.obs_dim,
        cfg.state_key,
        d.action_dim,
        cfg.action_key,
        imported.fps,
        d.task
    );
    if !imported.ignored.is_empty() {
        println!("not imported: {}", imported.ignored.join(", "));
    }
    if !imported.episodes_checked {
        println!("note: no episodes metadata in meta/; episode lengths were not cross-checked");
    }
    Ok(ExitCode::SUCCESS)
}
