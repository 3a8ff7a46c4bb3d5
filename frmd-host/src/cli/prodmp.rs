//! `frmd prodmp check`: compares the ProDMP decoder with reference vectors.
use clap::Subcommand;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Subcommand, Debug)]
pub enum ProdmpCommand {
    /// Decode every case of a vectors file with the f64 and baked f32 paths and report errors.
    Check {
        /// Vectors file in the schema of shared/testdata/prodmp_vectors.json.
        #[arg(long)]
        vectors: PathBuf,
    },
}

pub fn run(cmd: ProdmpCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        ProdmpCommand::Check { vectors } => {
            anyhow::bail!("not implemented yet: {}", vectors.display())
        }
    }
}
