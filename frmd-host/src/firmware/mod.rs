//! Processor in the loop: the `pil` firmware image (examples/cortex-m, src/bin/frmd-cortex-m-pil.rs)
//! under QEMU as a closed-loop policy.
//!
//! [`build`] builds (or reuses) the image for a core through `examples/cortex-m/run-qemu.sh`
//! (`FRMD_QEMU_BUILD_ONLY=1`), which owns the board table (target, machine, cpu) and the
//! toolchain setup; [`link::QemuLink`] starts QEMU with `-icount shift=0` and exchanges the frames
//! of `frmd_firmware_support::pil` with it over semihosting (the image's standard input and
//! output); [`policy::FirmwarePolicy`] implements the evaluator's [`crate::tasks::Policy`]
//! (and the server's `ServedPolicy`) on top, collecting the instructions the image counted for
//! every chunk.
use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use std::process::Command;

pub mod link;
pub mod lockstep;
pub mod policy;

/// A core `run-qemu.sh` boots (which of them build depends on the installed targets); written and
/// parsed as the script's board name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Board {
    /// Cortex-M4F (mps2-an386).
    M4,
    /// Cortex-M7 (mps2-an500, the M4's image).
    M7,
    /// Cortex-M33 (mps2-an505).
    M33,
    /// Cortex-M0 (micro:bit).
    M0,
    /// Cortex-M55 (mps3-an547, the M33's code).
    M55,
}

impl Board {
    /// Every board, in `run-qemu.sh`'s order.
    pub const ALL: [Board; 5] = [Board::M4, Board::M7, Board::M33, Board::M0, Board::M55];

    /// The board's name for `run-qemu.sh`.
    pub fn name(self) -> &'static str {
        match self {
            Board::M4 => "m4",
            Board::M7 => "m7",
            Board::M33 => "m33",
            Board::M0 => "m0",
            Board::M55 => "m55",
        }
    }
}

impl std::fmt::Display for Board {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Board {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> anyhow::Result<Self> {
        Board::ALL
            .into_iter()
            .find(|board| board.name() == text)
            .with_context(|| {
                let names: Vec<&str> = Board::ALL.iter().map(|b| b.name()).collect();
                format!(
                    "unknown firmware core `{text}`; expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// A built `pil` image and how QEMU runs it.
#[derive(Clone, Debug)]
pub struct FirmwareImage {
    /// The core (`m4`, `m7`, ...).
    pub board: String,
    pub elf: PathBuf,
    pub machine: String,
    pub cpu: String,
    pub qemu: PathBuf,
}

/// The repository this crate was built from (`run-qemu.sh` and the firmware sources live there).
pub fn default_repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Builds the `pil` image for `board` with `run-qemu.sh` (a no-op when it is up to date) and
/// returns where it is and how to boot it. `baked`: a baked module directory (`frmd export --out`,
/// MLP students) to bake into the image instead of the checked-in reach student.
pub fn build(repo: &Path, board: Board, baked: Option<&Path>) -> anyhow::Result<FirmwareImage> {
    let script = repo.join("examples/cortex-m/run-qemu.sh");
    anyhow::ensure!(
        script.is_file(),
        "{} not found (the firmware sources are needed to build the pil image)",
        script.display()
    );
    let mut command = Command::new("bash");
    command
        .arg(&script)
        .args([board.name(), "pil"])
        .env("FRMD_QEMU_BUILD_ONLY", "1")
        .env("CARGO_TARGET_DIR", repo.join("examples/cortex-m/target"))
        .env_remove("FRMD_PIL_BAKED");
    if let Some(dir) = baked {
        for file in ["policy.rs", "weights.bin"] {
            let path = dir.join(file);
            anyhow::ensure!(
                path.is_file(),
                "baked module {}: {file} missing (expected the output of `frmd export --out DIR`)",
                dir.display()
            );
        }
        let dir = dir
            .canonicalize()
            .with_context(|| format!("baked module {}", dir.display()))?;
        command.env("FRMD_PIL_BAKED", dir);
    }
    let output = command
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    if !output.status.success() {
        bail!(
            "building the pil image for {board} failed ({}):\n{}{}",
            output.status,
            stdout,
            tail(&String::from_utf8_lossy(&output.stderr), 40)
        );
    }
    let field = |key: &str| -> anyhow::Result<String> {
        let prefix = format!("{key}: ");
        stdout
            .lines()
            .find_map(|line| line.strip_prefix(prefix.as_str()))
            .map(str::to_owned)
            .with_context(|| {
                format!("run-qemu.sh {board} pil printed no `{key}:` line (output: {stdout})")
            })
    };
    Ok(FirmwareImage {
        board: board.to_string(),
        elf: PathBuf::from(field("elf")?),
        machine: field("machine")?,
        cpu: field("cpu")?,
        qemu: PathBuf::from(field("qemu")?),
    })
}

/// The last `lines` lines of `text`.
fn tail(text: &str, lines: usize) -> String {
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}
