//! Fuzzes the blob loaders (`LoadedMlp::load`, `LoadedMlp16::load`, `LoadedTransformer::load`)
//! and, for blobs that load, one policy step: any input must give `Ok` or a named error, never a
//! panic.
#![no_main]

use frmd_core::blob::{AlignedBlob, LoadedQuantMlp, LoadedTransformer};
use frmd_core::model::mlp::MlpPrecision;
use frmd_core::policy::Noise;
use frmd_core::rng::Rng;
use libfuzzer_sys::fuzz_target;

/// Loads `bytes` as an MLP blob with `A` activations and, if it loads, runs one chunk.
fn mlp_act_once<A: MlpPrecision + TryFrom<i16>>(bytes: &[u8]) {
    if let Ok(loaded) = LoadedQuantMlp::<A>::load(bytes) {
        // Capacities of a small policy: history 2, 3 observations, 2 DoF, horizon 6, 4 params.
        if let Ok(mut policy) = loaded.policy::<2, 3, 2, 6, 4, 64, 256>() {
            if policy.reset(&[0.0, 0.0]).is_ok() && policy.observe(&[0.0, 0.0, 0.0]).is_ok() {
                let _ = policy.act(Noise::Rng(&mut Rng::new(0)));
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    // As given (any alignment), then copied to an aligned buffer so that the checks after the
    // alignment test are reached too.
    let _ = LoadedQuantMlp::<i8>::load(data);
    let _ = LoadedQuantMlp::<i16>::load(data);
    let _ = LoadedTransformer::load(data);
    let aligned = AlignedBlob::new(data);
    let _ = LoadedTransformer::load(aligned.bytes());
    mlp_act_once::<i8>(aligned.bytes());
    mlp_act_once::<i16>(aligned.bytes());
});
