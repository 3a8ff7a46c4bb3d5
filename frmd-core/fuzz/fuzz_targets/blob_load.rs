//! Fuzzes the blob loaders (`LoadedMlp::load`, `LoadedTransformer::load`) and, for blobs that
//! load, one policy step: any input must give `Ok` or a named error, never a panic.
#![no_main]

use frmd_core::blob::{AlignedBlob, LoadedMlp, LoadedTransformer};
use frmd_core::policy::Noise;
use frmd_core::rng::Rng;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // As given (any alignment), then copied to an aligned buffer so that the checks after the
    // alignment test are reached too.
    let _ = LoadedMlp::load(data);
    let _ = LoadedTransformer::load(data);
    let aligned = AlignedBlob::new(data);
    let _ = LoadedTransformer::load(aligned.bytes());
    if let Ok(loaded) = LoadedMlp::load(aligned.bytes()) {
        // Capacities of a small policy: history 2, 3 observations, 2 DoF, horizon 6, 4 params.
        if let Ok(mut policy) = loaded.policy::<2, 3, 2, 6, 4, 64, 256>() {
            if policy.reset(&[0.0, 0.0]).is_ok() && policy.observe(&[0.0, 0.0, 0.0]).is_ok() {
                let _ = policy.act(Noise::Rng(&mut Rng::new(0)));
            }
        }
    };
});
