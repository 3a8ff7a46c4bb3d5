//! The self-describing blob form (DESIGN.md s.5); the format itself lives in
//! [`frmd_core::blob`], which also loads it.

use frmd_core::blob::{encode, encoded_len, BlobError};

use crate::QuantizedPolicy;

/// Writes `policy` as a blob (header, postcard descriptor, aligned sections). Fails with a
/// named error if a part's length disagrees with the stated shapes.
pub fn write(policy: &QuantizedPolicy) -> Result<Vec<u8>, BlobError> {
    policy.with_parts(|parts| {
        let mut out = vec![0_u8; encoded_len(parts)?];
        let written = encode(parts, &mut out)?;
        out.truncate(written);
        Ok(out)
    })
}
