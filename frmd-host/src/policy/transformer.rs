//! The int8 transformer-lite student as a closed-loop policy: frmd-core's
//! [`frmd_core::policy::Policy`] over a [`LoadedTransformer`] (the `FRMT` blob loader and
//! [`frmd_core::policy::Int8TransformerNetwork`], the firmware's code path), or over the
//! exporter's f32 reference ([`frmd_core::policy::F32TransformerNetwork`]) with the same blob
//! config. Compiled for the same shapes as the MLP runner ([`super::int8::SHAPES`]); the blob,
//! the loaded view and the scratch are leaked once per loaded policy.
use super::int8::{leak_aligned, ChunkRunner, Int8Policy, Runner, SHAPES};
use anyhow::{bail, Context};
use frmd_core::blob::{LoadedTransformer, TRANSFORMER_MAGIC};
use frmd_core::policy::{F32TransformerNetwork, Policy as CorePolicy};
use frmd_export::fold::MAX_WIDTH;
use frmd_export::transformer::{FoldedTransformer, HostScratch};

/// Whether `bytes` is a transformer blob (magic `FRMT`).
pub fn is_transformer_blob(bytes: &[u8]) -> bool {
    bytes.get(..4) == Some(&TRANSFORMER_MAGIC[..])
}

fn try_shape<const M: usize, const O: usize, const K: usize, const N: usize, const P: usize>(
    bytes: &'static [u8],
    f32_twin: Option<&'static FoldedTransformer>,
) -> Option<anyhow::Result<Box<dyn ChunkRunner>>> {
    let loaded = match LoadedTransformer::<M, O, K, N, P>::load(bytes) {
        Ok(l) => l,
        Err(frmd_core::blob::BlobError::DimensionMismatch(_)) => return None,
        Err(e) => return Some(Err(anyhow::anyhow!("transformer blob: {e}"))),
    };
    let loaded: &'static LoadedTransformer<'static, M, O, K, N, P> = Box::leak(Box::new(loaded));
    let scratch: &'static mut HostScratch = Box::leak(Box::new(HostScratch::new()));
    let policy_error = |e: frmd_core::policy::PolicyError| anyhow::anyhow!("transformer policy: {e}");
    Some(match f32_twin {
        None => {
            let blocks = Box::leak(Box::new(loaded.blocks()));
            loaded
                .network(blocks, scratch)
                .and_then(|net| CorePolicy::<'static, _, M, O, K, N, P, MAX_WIDTH>::new(loaded.config(), net))
                .map(|policy| Box::new(Runner { policy }) as Box<dyn ChunkRunner>)
                .map_err(policy_error)
        }
        Some(folded) => {
            let blocks = Box::leak(folded.f32_blocks().into_boxed_slice());
            let tokens: &'static [f32] = Box::leak(folded.flat_noise_tokens().into_boxed_slice());
            folded.view(blocks, 0).and_then(|model| {
                F32TransformerNetwork::new(model, &folded.layout, tokens, scratch)
                    .and_then(|net| CorePolicy::<'static, _, M, O, K, N, P, MAX_WIDTH>::new(loaded.config(), net))
                    .map(|policy| Box::new(Runner { policy }) as Box<dyn ChunkRunner>)
                    .map_err(policy_error)
            })
        }
    })
}

/// Loads a transformer blob into a runner of the matching compiled shape. With `f32_twin`, the
/// policy runs frmd-core's f32 transformer of the folded model instead of the blob's int8 one.
pub fn load_runner(bytes: &[u8], f32_twin: Option<FoldedTransformer>) -> anyhow::Result<Box<dyn ChunkRunner>> {
    if !is_transformer_blob(bytes) {
        bail!("not a transformer blob (magic {:?}, expected FRMT)", bytes.get(..4));
    }
    let bytes = leak_aligned(bytes);
    let twin: Option<&'static FoldedTransformer> = f32_twin.map(|f| &*Box::leak(Box::new(f)));
    let found = try_shape::<2, 6, 2, 12, 21>(bytes, twin)
        .or_else(|| try_shape::<2, 9, 2, 12, 21>(bytes, twin))
        .or_else(|| try_shape::<2, 10, 2, 12, 21>(bytes, twin))
        .or_else(|| try_shape::<2, 7, 2, 12, 21>(bytes, twin))
        .or_else(|| try_shape::<2, 6, 2, 8, 7>(bytes, twin));
    match found {
        Some(runner) => runner,
        None => bail!("the transformer blob's sizes are not among the host's compiled shapes (M, O, K, N, P) {SHAPES:?}"),
    }
}

/// The int8 policy of an MLP (`FRMD`) or transformer (`FRMT`) blob, chosen by its magic.
pub fn int8_policy(bytes: &[u8], label: &str) -> anyhow::Result<Int8Policy> {
    if is_transformer_blob(bytes) {
        Ok(Int8Policy::from_runner(load_runner(bytes, None)?, label))
    } else {
        Int8Policy::from_blob(bytes, label)
    }
}

/// The transformer blob's runtime policy with the f32 reference network of `folded`.
pub fn f32_twin(bytes: &[u8], folded: FoldedTransformer, label: &str) -> anyhow::Result<Int8Policy> {
    Ok(Int8Policy::from_runner(load_runner(bytes, Some(folded)).context("f32 twin")?, label))
}
