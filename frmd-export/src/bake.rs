//! The baked form: a generated Rust module (needs only frmd-core) that a firmware compiles in,
//! here what both backbones' generators share. Every generated module has no inner attributes,
//! so it works as a plain file module (`mod policy;`) and with `include!` from a build script's
//! `OUT_DIR` (`mod baked { include!(concat!(env!("OUT_DIR"), "/policy.rs")); }`), its data files
//! beside it, and offers the same items whatever the backbone:
//!
//! - the sizes `HISTORY`, `OBS_DIM`, `ACTION_DIM`, `HORIZON`, `PARAMS_PER_DOF`, `INPUT_WIDTH`,
//!   `NUM_STEPS` and the read-only bytes `FLASH_BYTES`;
//! - `Storage` (what the policy borrows besides the module's statics; `Storage::new()` is `const`,
//!   so it can be a `static`), the `BakedPolicy` type and `policy(&mut Storage)`, which returns a
//!   checked policy (call `reset` before the first chunk).
//!
//! The MLP's module ([`crate::mlp::bake`]) holds const tables plus an aligned `weights.bin`; the
//! transformer's ([`crate::transformer::bake`]) embeds the blob and loads it with frmd-core's
//! checked loader.
use anyhow::Context;
use std::path::{Path, PathBuf};

use crate::fold::ProDmpTablesOwned;

/// File name of the generated module.
pub const MODULE_FILE: &str = "policy.rs";
/// File name of the MLP module's weight file.
pub const WEIGHTS_FILE: &str = "weights.bin";
/// File name of the blob written beside every module (embedded by the transformer's).
pub const BLOB_FILE: &str = "policy.blob";

/// `[a, b, c]` with each value formatted by `f`.
pub(crate) fn list<T>(values: &[T], f: impl Fn(&T) -> String) -> String {
    let items: Vec<String> = values.iter().map(f).collect();
    format!("[{}]", items.join(", "))
}

/// An f32 literal that reads back to the same bits (`{:?}` is the shortest round-trip form).
pub(crate) fn float(value: &f32) -> String {
    format!("{value:?}")
}

/// The tables of a baked ProDMP decoder as a Rust expression `BakedProDmp { pos_params: .., .. }`
/// (`BakedProDmp` = `frmd_core::prodmp::BakedProDmp` must be in scope), every f32 as a literal that
/// reads back to the same bits; `params_per_dof` values per row of the `[N][P]` tables. The
/// generated policy module's `DECODER` and the firmware's stand-alone decoder use it.
pub fn decoder_expression(prodmp: &ProDmpTablesOwned, params_per_dof: usize) -> String {
    let rows = |table: &[f32]| {
        let rows: Vec<String> = table
            .chunks(params_per_dof.max(1))
            .map(|row| format!("        {},", list(row, float)))
            .collect();
        format!("[\n{}\n    ]", rows.join("\n"))
    };
    format!(
        "BakedProDmp {{\n    pos_params: {},\n    vel_params: {},\n    pos_y0: {},\n    pos_v0: {},\n    vel_y0: {},\n    vel_v0: {},\n}}",
        rows(&prodmp.pos_params),
        rows(&prodmp.vel_params),
        list(&prodmp.pos_y0, float),
        list(&prodmp.pos_v0, float),
        list(&prodmp.vel_y0, float),
        list(&prodmp.vel_v0, float)
    )
}

/// Writes `files` (name, bytes) into `dir` (created if missing), each atomically; returns their
/// paths.
pub(crate) fn write_files(dir: &Path, files: &[(&str, &[u8])]) -> anyhow::Result<Vec<PathBuf>> {
    let write = || -> anyhow::Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir)?;
        files
            .iter()
            .map(|(name, bytes)| {
                let path = dir.join(name);
                frmd_formats::artifact::write_atomic(&path, bytes)?;
                Ok(path)
            })
            .collect()
    };
    write().with_context(|| format!("writing {}", dir.display()))
}
