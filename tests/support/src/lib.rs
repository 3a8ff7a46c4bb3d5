//! Fixtures the FRMD tests share.
//!
//! - [`random_policy`]: a deterministic random exported MLP policy ([`frmd_export::QuantizedPolicy`])
//!   with valid parameters, of any shape;
//! - [`AlignedBlob`]: blob bytes in 4-aligned memory, as the loaders read them in place.

pub mod random_policy;

/// Blob bytes copied into 16-aligned memory (a `Vec<u8>` has no alignment guarantee).
pub struct AlignedBlob {
    words: Vec<u128>,
    len: usize,
}

impl AlignedBlob {
    pub fn new(bytes: &[u8]) -> Self {
        let mut words = vec![0_u128; bytes.len().div_ceil(16)];
        bytemuck::cast_slice_mut::<u128, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
        AlignedBlob {
            words,
            len: bytes.len(),
        }
    }

    pub fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u128, u8>(&self.words)[..self.len]
    }
}
