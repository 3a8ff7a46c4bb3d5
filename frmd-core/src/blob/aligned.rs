//! [`AlignedBlob`]: blob bytes copied into heap memory aligned for the loaders (feature `alloc`;
//! a firmware keeps its blob in a `static` [`AlignedBytes`](crate::policy::AlignedBytes) instead).
//! The one owned blob buffer of the std tools, their tests and the fuzz targets.

use alloc::vec;
use alloc::vec::Vec;

/// Blob bytes in 16-aligned memory (a `Vec<u8>` has no alignment guarantee; the loaders read a
/// blob in place and need it 4-aligned, every section offset is a multiple of 16).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AlignedBlob {
    words: Vec<u128>,
    start: usize,
    len: usize,
}

impl AlignedBlob {
    /// A copy of `bytes` starting at a 16-aligned address.
    pub fn new(bytes: &[u8]) -> Self {
        Self::shifted(bytes, 0)
    }

    /// A copy of `bytes` starting `shift` bytes after a 16-aligned address (tests of the
    /// loaders' alignment checks).
    pub fn shifted(bytes: &[u8], shift: usize) -> Self {
        let mut words = vec![0_u128; (shift + bytes.len()).div_ceil(16)];
        let raw: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
        if let Some(target) = raw.get_mut(shift..shift + bytes.len()) {
            target.copy_from_slice(bytes);
        }
        Self {
            words,
            start: shift,
            len: bytes.len(),
        }
    }

    /// The blob bytes.
    pub fn bytes(&self) -> &[u8] {
        let raw: &[u8] = bytemuck::cast_slice(&self.words);
        raw.get(self.start..self.start + self.len).unwrap_or(&[])
    }
}

#[cfg(test)]
mod tests {
    use super::AlignedBlob;

    #[test]
    fn copies_are_aligned_and_whole() {
        let bytes: alloc::vec::Vec<u8> = (0..37).collect();
        for shift in [0, 1, 4, 15, 16] {
            let blob = AlignedBlob::shifted(&bytes, shift);
            assert_eq!(blob.bytes(), &bytes[..]);
            assert_eq!(blob.bytes().as_ptr() as usize % 16, shift % 16);
        }
        assert_eq!(AlignedBlob::new(&[]).bytes(), &[] as &[u8]);
    }
}
