//! Support for generated (baked) policy modules: an aligned wrapper for `include_bytes!` data and
//! a checked cast of one of its sections.
//!
//! A generated module holds
//! `static WEIGHTS: AlignedBytes<LEN> = AlignedBytes(*include_bytes!("weights.bin"));`
//! and builds its layers from [`baked_slice`] views of `WEIGHTS.0` at run time (bytemuck casts
//! are not `const`), so no `unsafe` and no unchecked alignment assumption is involved.

use super::PolicyError;

/// `L` bytes aligned to 16 (enough for every element type of the weight file).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AlignedBytes<const L: usize>(pub [u8; L]);

/// `len` elements of `T` at byte `offset` of `bytes`; `Err(BakedData)` when out of range or
/// misaligned for `T`.
pub fn baked_slice<T: bytemuck::Pod>(
    bytes: &[u8],
    offset: usize,
    len: usize,
) -> Result<&[T], PolicyError> {
    let byte_len = len
        .checked_mul(core::mem::size_of::<T>())
        .ok_or(PolicyError::BakedData)?;
    let end = offset.checked_add(byte_len).ok_or(PolicyError::BakedData)?;
    let raw = bytes.get(offset..end).ok_or(PolicyError::BakedData)?;
    bytemuck::try_cast_slice(raw).map_err(|_| PolicyError::BakedData)
}

#[cfg(test)]
mod tests {
    use super::*;

    static DATA: AlignedBytes<16> = AlignedBytes([
        1, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0, 0x80, 0x3F, 7, 8, 9, 10,
    ]);

    #[test]
    fn casts_checked_sections() {
        assert_eq!(baked_slice::<i32>(&DATA.0, 0, 2), Ok(&[1, -1][..]));
        assert_eq!(baked_slice::<f32>(&DATA.0, 8, 1), Ok(&[1.0_f32][..]));
        assert_eq!(baked_slice::<i8>(&DATA.0, 12, 4), Ok(&[7_i8, 8, 9, 10][..]));
        assert_eq!(
            baked_slice::<i32>(&DATA.0, 2, 1),
            Err(PolicyError::BakedData)
        );
        assert_eq!(
            baked_slice::<i32>(&DATA.0, 12, 2),
            Err(PolicyError::BakedData)
        );
        assert_eq!(
            baked_slice::<i32>(&DATA.0, usize::MAX, 1),
            Err(PolicyError::BakedData)
        );
        assert_eq!(
            baked_slice::<i32>(&DATA.0, 0, usize::MAX),
            Err(PolicyError::BakedData)
        );
    }
}
