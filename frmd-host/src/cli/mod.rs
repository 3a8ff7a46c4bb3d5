//! `frmd` subcommands. Each subcommand owns one file here with its clap `Args`, which map onto a
//! library config struct (every default is read from the config's `Default`), and a `run` that
//! calls the library and prints the result. Nothing outside this module calls into it.
use clap::{Parser, Subcommand};
use std::process::ExitCode;

pub(crate) mod bench;
pub(crate) mod collect;
pub(crate) mod equiv;
pub(crate) mod eval;
pub(crate) mod eval_firmware;
pub(crate) mod export;
pub(crate) mod import;
pub(crate) mod prodmp;
pub(crate) mod quickstart;
pub(crate) mod serve;
pub(crate) mod train;

/// FRMD: from demonstrations to a one-step diffusion policy in controller firmware.
#[derive(Parser, Debug)]
#[command(name = "frmd", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// ProDMP decoder tools (check against reference vectors).
    #[command(subcommand)]
    Prodmp(prodmp::ProdmpCommand),
    /// Run a task's scripted expert and write a demonstration dataset (safetensors).
    Collect(collect::CollectArgs),
    /// Convert demonstrations from another format (a LeRobot dataset) into a dataset file.
    #[command(subcommand)]
    Import(import::ImportCommand),
    /// Closed-loop evaluation of a policy on a task.
    Eval(eval::EvalArgs),
    /// Train a teacher, distill a student, or train the DP baseline.
    #[command(subcommand)]
    Train(train::TrainCommand),
    /// Latency per action chunk of every policy kind side by side, with ratios (one run).
    #[command(visible_alias = "latency")]
    Bench(bench::BenchArgs),
    /// The whole pipeline on a built-in task in minutes: collect, train, export, evaluate.
    Quickstart(quickstart::QuickstartArgs),
    /// Quantize a student checkpoint: baked Rust module and/or blob, with RAM/flash figures.
    Export(export::ExportArgs),
    /// Serve a policy over the binary protocol of docs/serve-protocol.md (stdin/stdout or a
    /// Unix socket), for clients with their own simulator or robot.
    Serve(serve::ServeArgs),
    /// Bit-accuracy harness: core f32 / int8 vs the float student, kernels vs a wide-integer model.
    Equiv(equiv::EquivArgs),
}

/// Parses the command line, runs the subcommand, and maps errors to a non-zero exit code.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Prodmp(cmd) => prodmp::run(cmd),
        Command::Collect(args) => collect::run(args),
        Command::Import(cmd) => import::run(cmd),
        Command::Eval(args) => eval::run(args),
        Command::Train(cmd) => train::run(cmd),
        Command::Bench(args) => bench::run(args),
        Command::Quickstart(args) => quickstart::run(args),
        Command::Export(args) => export::run(args),
        Command::Equiv(args) => equiv::run(args),
        Command::Serve(args) => serve::run(args),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::from(2)
        }
    }
}
