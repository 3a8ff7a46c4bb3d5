//! `frmd serve`: one policy behind the binary protocol of docs/serve-protocol.md, on
//! stdin/stdout or a Unix socket. The server itself is `crate::serve`.
use crate::diffusion::samplers::Solver;
use crate::firmware::Board;
use crate::serve::{self, FloatType, PolicySource, ServeConfig};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
#[command(group = clap::ArgGroup::new("policy").required(true).multiple(true).args(["ckpt", "baked", "blob", "firmware"]))]
pub struct ServeArgs {
    /// Float checkpoint directory to serve (teacher, student or DP).
    #[arg(long)]
    pub ckpt: Option<PathBuf>,
    /// Sampling steps for --ckpt (defaults: teacher 10, student 1, DP 10 = DDIM; DP 100 = DDPM).
    #[arg(long, requires = "ckpt")]
    pub steps: Option<usize>,
    /// Teacher ODE solver for --ckpt: euler | heun | dpm++2m.
    #[arg(long, requires = "ckpt")]
    pub solver: Option<Solver>,
    /// Baked module directory (`frmd export --out`): serves the int8 blob written beside it.
    #[arg(long)]
    pub baked: Option<PathBuf>,
    /// int8 blob file (`frmd export --blob`) to serve.
    #[arg(long)]
    pub blob: Option<PathBuf>,
    /// Serve through the `pil` firmware image under QEMU on this core (m4, m7, m33, m0, m55):
    /// bakes --baked DIR's module (default: the checked-in reach student) and answers every ACT
    /// with the emulated MCU's chunk.
    #[arg(long, value_name = "CORE")]
    pub firmware: Option<Board>,
    /// Listen on this Unix socket path instead of stdin/stdout (one client at a time).
    #[arg(long)]
    pub socket: Option<PathBuf>,
    /// With --socket: exit after this many connections (default: serve until killed).
    #[arg(long, requires = "socket")]
    pub connections: Option<usize>,
    /// Value type of observations and actions on the wire: f32 | f64.
    #[arg(long, default_value_t = FloatType::F32)]
    pub float: FloatType,
    /// Actions the client should execute from each chunk (announced in HELLO_OK; default 8 or
    /// the horizon if shorter).
    #[arg(long)]
    pub exec_steps: Option<u16>,
    /// Control period in seconds announced in HELLO_OK (default: the checkpoint's).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Previous action before an episode's first chunk when RESET gives none, comma-separated
    /// (default: zeros).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub init_action: Option<Vec<f64>>,
    /// Answer every ACT with a zero chunk of the model's shape without running it (measures
    /// the protocol's own cost).
    #[arg(long)]
    pub zeros: bool,
}

pub fn run(args: ServeArgs) -> anyhow::Result<ExitCode> {
    let source = match (&args.ckpt, &args.baked, &args.blob, &args.firmware) {
        (Some(dir), None, None, None) => PolicySource::Checkpoint { dir: dir.clone(), steps: args.steps, solver: args.solver },
        (None, baked, None, Some(board)) => PolicySource::Firmware { board: *board, baked: baked.clone() },
        (None, Some(dir), None, None) => PolicySource::Baked(dir.clone()),
        (None, None, Some(path), None) => PolicySource::Blob(path.clone()),
        _ => anyhow::bail!("pass exactly one of --ckpt, --baked, --blob (or --firmware CORE, optionally with --baked DIR)"),
    };
    let cfg = ServeConfig {
        float_type: args.float,
        exec_steps: args.exec_steps,
        dt: args.dt,
        init_action: args.init_action.clone(),
        zeros: args.zeros,
    };
    let mut served = serve::load(&source, &cfg)?;
    let info = &served.info;
    eprintln!(
        "frmd serve: {} (obs {} x {}, action {} x {}, exec {}, dt {} s, {:?}), protocol v{}",
        info.name,
        info.obs_history,
        info.obs_dim,
        info.horizon,
        info.action_dim,
        info.exec_steps,
        info.dt,
        info.float_type,
        serve::VERSION
    );
    match &args.socket {
        #[cfg(unix)]
        Some(path) => {
            serve::serve_socket(&mut served, path, args.connections)?;
            Ok(ExitCode::SUCCESS)
        }
        #[cfg(not(unix))]
        Some(_) => anyhow::bail!("--socket needs a Unix system"),
        None => match serve::serve_stdio(&mut served) {
            Ok(serve::StreamEnd::Closed | serve::StreamEnd::Eof) => Ok(ExitCode::SUCCESS),
            Ok(serve::StreamEnd::Truncated) => Ok(ExitCode::from(1)),
            Err(e) => {
                eprintln!("frmd serve: {e:#}");
                Ok(ExitCode::from(1))
            }
        },
    }
}
