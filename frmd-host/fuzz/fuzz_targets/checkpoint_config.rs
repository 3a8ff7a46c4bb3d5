//! Fuzzes `CheckpointMeta::from_json` (parse and validate a `frmd.json`) and, for configs that
//! validate, what the loaders derive from them (tensor list, ProDMP config): any input must give
//! `Ok` or a named error, never a panic or an unbounded allocation.
#![no_main]

use frmd_formats::checkpoint::{expected_tensors, CheckpointMeta};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(meta) = CheckpointMeta::from_json(data) {
        let _ = expected_tensors(&meta.model);
        let _ = meta.model.prodmp();
    }
});
