//! Fuzzes `Dataset::from_bytes` (the validating reader of demonstration files): any input must
//! give `Ok` or a named error, never a panic.
#![no_main]

use frmd_host::data::Dataset;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(dataset) = Dataset::from_bytes(data) {
        let _ = dataset.episode_ranges();
        let _ = dataset.windows(2, 4);
    }
});
