//! The `frmd` command-line tool. Every subcommand lives in `frmd_host::cli`.
use mimalloc::MiMalloc;

#[global_allocator]
static GLOBAL: MiMalloc = MiMalloc;

fn main() -> std::process::ExitCode {
    frmd_host::cli::main()
}
