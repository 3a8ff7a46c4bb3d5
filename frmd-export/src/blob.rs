//! The self-describing blob forms (docs/design.md s.5) of both backbones; the formats themselves live
//! in [`frmd_core::blob`], which writes them from frmd-core views and loads them.

use frmd_core::blob::{
    encode_mlp, encode_transformer, mlp_encoded_len, transformer_encoded_len, BlobError,
    TransformerBlobParts,
};

use crate::checkpoint::Normalization;
use crate::transformer::QuantizedTransformer;
use crate::QuantizedPolicy;

/// Writes `policy` as an MLP blob. Fails with a named error if a part's length disagrees with
/// the stated shapes.
pub fn write(policy: &QuantizedPolicy) -> Result<Vec<u8>, BlobError> {
    policy.with_parts(|parts| {
        let mut out = vec![0_u8; mlp_encoded_len(parts)?];
        let written = encode_mlp(parts, &mut out)?;
        out.truncate(written);
        Ok(out)
    })
}

/// Writes `model` with normalization `norm` as a transformer blob. Fails with a named error if
/// a size does not fit the format (more than [`frmd_core::blob::transformer::MAX_BLOCKS`]
/// blocks, sizes beyond u32); the loader checks every shape.
pub fn write_transformer(
    model: &QuantizedTransformer,
    norm: &Normalization,
) -> Result<Vec<u8>, BlobError> {
    let blocks = model.int8_blocks();
    let noise_tokens = model.folded.flat_noise_tokens();
    let parts = TransformerBlobParts {
        config: model.folded.config(norm),
        model: model.view(&blocks, 0).map_err(|_| BlobError::Encode)?,
        noise_tokens: &noise_tokens,
    };
    let mut out = vec![0_u8; transformer_encoded_len(&parts)?];
    let written = encode_transformer(&parts, &mut out)?;
    out.truncate(written);
    Ok(out)
}
