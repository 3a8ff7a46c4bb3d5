//! The container every blob shares: fixed header, postcard descriptor, aligned sections; its
//! parse side (`parse`, `Data`) and its emit side (`encode`, `SectionWriter`).
//!
//! ```text
//! offset  size  field (little endian)
//!  0      4     magic (b"FRMD": MLP, b"FRMT": transformer)
//!  4      2     format version (u16, FORMAT_VERSION)
//!  6      2     reserved, 0
//!  8      4     total length in bytes, header included (u32)
//! 12      4     CRC-32 (IEEE) of bytes [HEADER_LEN, total length)
//! 16      4     descriptor length in bytes (u32)
//! 20      ..    descriptor (postcard, the format's descriptor type)
//! D       ..    data area, D = align_up(20 + descriptor length, SECTION_ALIGN)
//! ```
//! Every section is a `(offset, len)` byte range relative to the data area start `D`, with the
//! offset a multiple of [`SECTION_ALIGN`]; gaps are zero. Multi-byte values are little endian, so
//! the blob is read in place on little-endian targets (Cortex-M, x86-64, aarch64); the loader
//! needs the blob to start at a 4-byte aligned address (it checks, see
//! [`BlobError::SectionMisaligned`]).
//!
//! The container knows no format's sections: a format names each section it reads with its own
//! tag ([`SectionId`]), which the checks here only pass on into their errors.

use bytemuck::PodCastError;
use serde::{Deserialize, Serialize};

use super::crc32::crc32;
use super::{BlobError, SectionId};

/// The format version this crate writes. Version 3 turned the MLP descriptor's two-plane flag
/// into an input precision code (adding the 16-bit input plane); postcard encodes the old `bool`
/// as the byte 0 or 1, which is the same code, so version 2 blobs read unchanged. Version 4 adds
/// a trailer to the MLP descriptor (activation precision and int16 clamps, `blob::mlp`); a
/// version 2 or 3 MLP blob has none and reads as int8 activations. Transformer blobs are the same
/// in versions 2 to 4; version 5 adds a trailer to the transformer descriptor (activation
/// precision, `blob::transformer`), and an older transformer blob reads as int8 activations. MLP
/// blobs are the same in versions 4 and 5.
pub const FORMAT_VERSION: u16 = 5;
/// The oldest format version this crate reads.
pub const MIN_FORMAT_VERSION: u16 = 2;
/// Header length in bytes (the descriptor starts here).
pub const HEADER_LEN: usize = 20;
/// Alignment of the data area and of every section offset, in bytes.
pub const SECTION_ALIGN: usize = 16;

/// A byte range of the data area.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Section {
    /// Start, relative to the data area, a multiple of [`SECTION_ALIGN`].
    pub offset: u32,
    /// Length in bytes.
    pub len: u32,
}

/// `value` rounded up to a multiple of `align` (a power of two); `None` on overflow.
pub(crate) fn align_up(value: usize, align: usize) -> Option<usize> {
    let mask = align.checked_sub(1)?;
    value.checked_add(mask).map(|v| v & !mask)
}

/// Byte offset of the data area for a descriptor of `descriptor_len` bytes.
pub(crate) fn data_start(descriptor_len: usize) -> Option<usize> {
    align_up(HEADER_LEN.checked_add(descriptor_len)?, SECTION_ALIGN)
}

// ----- parse side -----

/// The data area and checked views of its sections.
pub(crate) struct Data<'a> {
    pub(crate) bytes: &'a [u8],
}

impl<'a> Data<'a> {
    /// Section `section` as `T` elements (aligned, whole elements, inside the data area).
    pub(crate) fn cast<T: bytemuck::Pod>(
        &self,
        section: Section,
        id: SectionId,
    ) -> Result<&'a [T], BlobError> {
        let start = section.offset as usize;
        if !start.is_multiple_of(SECTION_ALIGN) {
            return Err(BlobError::SectionMisaligned(id));
        }
        let end = start
            .checked_add(section.len as usize)
            .ok_or(BlobError::SectionBounds(id))?;
        let raw = self
            .bytes
            .get(start..end)
            .ok_or(BlobError::SectionBounds(id))?;
        bytemuck::try_cast_slice(raw).map_err(|e| match e {
            PodCastError::TargetAlignmentGreaterAndInputNotAligned
            | PodCastError::AlignmentMismatch => BlobError::SectionMisaligned(id),
            PodCastError::OutputSliceWouldHaveSlop | PodCastError::SizeMismatch => {
                BlobError::SectionLength(id)
            }
        })
    }

    /// Section of exactly `count` elements.
    pub(crate) fn exact<T: bytemuck::Pod>(
        &self,
        section: Section,
        count: Option<usize>,
        id: SectionId,
    ) -> Result<&'a [T], BlobError> {
        let values = self.cast::<T>(section, id)?;
        if Some(values.len()) == count {
            Ok(values)
        } else {
            Err(BlobError::SectionLength(id))
        }
    }

    /// f32 section of any length, all finite.
    pub(crate) fn finite_any(
        &self,
        section: Section,
        id: SectionId,
    ) -> Result<&'a [f32], BlobError> {
        let values = self.cast::<f32>(section, id)?;
        if values.iter().all(|v| v.is_finite()) {
            Ok(values)
        } else {
            Err(BlobError::NonFinite(id))
        }
    }

    /// f32 section of exactly `count` finite values.
    pub(crate) fn finite(
        &self,
        section: Section,
        count: Option<usize>,
        id: SectionId,
    ) -> Result<&'a [f32], BlobError> {
        let values = self.exact::<f32>(section, count, id)?;
        if values.iter().all(|v| v.is_finite()) {
            Ok(values)
        } else {
            Err(BlobError::NonFinite(id))
        }
    }
}

fn read_u16(bytes: &[u8], at: usize) -> Result<u16, BlobError> {
    let raw = bytes.get(at..at + 2).ok_or(BlobError::Truncated)?;
    let mut word = [0_u8; 2];
    word.copy_from_slice(raw);
    Ok(u16::from_le_bytes(word))
}

fn read_u32(bytes: &[u8], at: usize) -> Result<u32, BlobError> {
    let raw = bytes.get(at..at + 4).ok_or(BlobError::Truncated)?;
    let mut word = [0_u8; 4];
    word.copy_from_slice(raw);
    Ok(u32::from_le_bytes(word))
}

/// Checks the header and (with `check_crc`) the CRC; returns the format version, the descriptor
/// bytes and the data area.
fn split(bytes: &[u8], magic: [u8; 4], check_crc: bool) -> Result<(u16, &[u8], &[u8]), BlobError> {
    if cfg!(target_endian = "big") {
        return Err(BlobError::BigEndianTarget);
    }
    let header = bytes.get(..HEADER_LEN).ok_or(BlobError::Truncated)?;
    if header.get(..4) != Some(&magic[..]) {
        return Err(BlobError::BadMagic);
    }
    let version = read_u16(header, 4)?;
    if !(MIN_FORMAT_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(BlobError::UnsupportedVersion { found: version });
    }
    if read_u16(header, 6)? != 0 {
        return Err(BlobError::ReservedField);
    }
    let total = read_u32(header, 8)? as usize;
    let stored = read_u32(header, 12)?;
    let desc_len = read_u32(header, 16)? as usize;
    if total < HEADER_LEN {
        return Err(BlobError::InvalidLength);
    }
    let blob = bytes.get(..total).ok_or(BlobError::Truncated)?;
    let payload = blob.get(HEADER_LEN..).ok_or(BlobError::InvalidLength)?;
    let start = data_start(desc_len).ok_or(BlobError::InvalidLength)?;
    if start > total {
        return Err(BlobError::InvalidLength);
    }
    if check_crc {
        let computed = crc32(payload);
        if computed != stored {
            return Err(BlobError::CrcMismatch { stored, computed });
        }
    }
    let descriptor = payload.get(..desc_len).ok_or(BlobError::InvalidLength)?;
    let data = blob.get(start..).ok_or(BlobError::InvalidLength)?;
    Ok((version, descriptor, data))
}

/// Checks the header and (with `check_crc`) the CRC and decodes the descriptor, for a descriptor
/// that gained a trailer `T` in format version `trailer_since`: blobs
/// of that version or later must carry it (`Some`), older ones must not (`None`).
pub(crate) fn parse_versioned<'a, D: Deserialize<'a>, T: Deserialize<'a>>(
    bytes: &'a [u8],
    magic: [u8; 4],
    check_crc: bool,
    trailer_since: u16,
) -> Result<(D, Option<T>, Data<'a>), BlobError> {
    let (version, descriptor_bytes, data_bytes) = split(bytes, magic, check_crc)?;
    let (descriptor, rest) =
        postcard::take_from_bytes::<D>(descriptor_bytes).map_err(|_| BlobError::Descriptor)?;
    let (trailer, rest) = if version >= trailer_since {
        let (trailer, rest) =
            postcard::take_from_bytes::<T>(rest).map_err(|_| BlobError::Descriptor)?;
        (Some(trailer), rest)
    } else {
        (None, rest)
    };
    if !rest.is_empty() {
        return Err(BlobError::Descriptor);
    }
    Ok((descriptor, trailer, Data { bytes: data_bytes }))
}

// ----- emit side -----

/// Lays out sections in order, each at the next multiple of [`SECTION_ALIGN`]: measuring only
/// (to size the blob) or writing into the data area.
pub(crate) struct SectionWriter<'b> {
    out: Option<&'b mut [u8]>,
    /// Where the next section starts.
    cursor: usize,
    /// End of the last section: the data area's length.
    end: usize,
}

impl<'b> SectionWriter<'b> {
    fn new(out: Option<&'b mut [u8]>) -> Self {
        Self {
            out,
            cursor: 0,
            end: 0,
        }
    }

    /// The next section: `values` as little-endian bytes of `B` each.
    fn put<const B: usize, T: Copy>(
        &mut self,
        values: impl Iterator<Item = T> + Clone,
        to_bytes: impl Fn(T) -> [u8; B],
    ) -> Result<Section, BlobError> {
        self.section(values.clone().count(), B, |target| {
            for (chunk, value) in target.chunks_exact_mut(B).zip(values) {
                chunk.copy_from_slice(&to_bytes(value));
            }
        })
    }

    /// The next section: `count` elements of `size` bytes, written by `write` into the section's
    /// bytes (when writing rather than measuring).
    fn section(
        &mut self,
        count: usize,
        size: usize,
        write: impl FnOnce(&mut [u8]),
    ) -> Result<Section, BlobError> {
        let len = count.checked_mul(size).ok_or(BlobError::TooLarge)?;
        let offset = self.cursor;
        let end = offset.checked_add(len).ok_or(BlobError::TooLarge)?;
        if let Some(out) = self.out.as_deref_mut() {
            write(out.get_mut(offset..end).ok_or(BlobError::BufferTooSmall)?);
        }
        self.end = end;
        self.cursor = align_up(end, SECTION_ALIGN).ok_or(BlobError::TooLarge)?;
        Ok(Section {
            offset: u32::try_from(offset).map_err(|_| BlobError::TooLarge)?,
            len: u32::try_from(len).map_err(|_| BlobError::TooLarge)?,
        })
    }

    /// An f32 section.
    pub(crate) fn f32s<'v>(
        &mut self,
        values: impl Iterator<Item = &'v f32> + Clone,
    ) -> Result<Section, BlobError> {
        self.put(values.copied(), f32::to_le_bytes)
    }

    /// An i32 section.
    pub(crate) fn i32s(&mut self, values: &[i32]) -> Result<Section, BlobError> {
        self.put(values.iter().copied(), i32::to_le_bytes)
    }

    /// A section of integers, each little endian, as many per part of `parts` as it has (the
    /// parts back to back). Written from the values' bytes, so it refuses to run on a big-endian
    /// target ([`BlobError::BigEndianTarget`], as the loader does).
    pub(crate) fn ints<'v, T: bytemuck::Pod>(
        &mut self,
        parts: impl Iterator<Item = &'v [T]> + Clone,
    ) -> Result<Section, BlobError> {
        if cfg!(target_endian = "big") {
            return Err(BlobError::BigEndianTarget);
        }
        let count = parts.clone().map(<[T]>::len).sum();
        self.section(count, core::mem::size_of::<T>(), |target| {
            let mut at = 0;
            for part in parts {
                let bytes: &[u8] = bytemuck::cast_slice(part);
                if let Some(slot) = target.get_mut(at..at + bytes.len()) {
                    slot.copy_from_slice(bytes);
                }
                at += bytes.len();
            }
        })
    }

    /// An i8 section.
    pub(crate) fn i8s<'v>(
        &mut self,
        values: impl Iterator<Item = &'v i8> + Clone,
    ) -> Result<Section, BlobError> {
        self.put(values.copied(), i8::to_le_bytes)
    }

    /// A u32 section.
    pub(crate) fn u32s(
        &mut self,
        values: impl Iterator<Item = u32> + Clone,
    ) -> Result<Section, BlobError> {
        self.put(values, u32::to_le_bytes)
    }

    /// Extends the data area to the next multiple of [`SECTION_ALIGN`] (MLP blobs end there;
    /// transformer blobs end with their last section).
    pub(crate) fn pad_end(&mut self) {
        self.end = self.cursor;
    }
}

fn descriptor_len<D: Serialize>(descriptor: &D) -> Result<usize, BlobError> {
    postcard::serialize_with_flavor(descriptor, postcard::ser_flavors::Size::default())
        .map_err(|_| BlobError::Encode)
}

/// Length of the blob `encode` writes for `emit`.
pub(crate) fn encoded_len<D: Serialize>(
    mut emit: impl FnMut(&mut SectionWriter<'_>) -> Result<D, BlobError>,
) -> Result<usize, BlobError> {
    let mut measure = SectionWriter::new(None);
    let descriptor = emit(&mut measure)?;
    data_start(descriptor_len(&descriptor)?)
        .and_then(|start| start.checked_add(measure.end))
        .ok_or(BlobError::TooLarge)
}

/// Writes a blob into the front of `out` and returns its length: `emit` lays out the sections
/// (it runs twice, measuring then writing, and must lay them out alike both times) and returns
/// the descriptor, which is written after the header; the header gets `magic`, the lengths and
/// the payload CRC. The rest of `out` is untouched.
pub(crate) fn encode<D: Serialize>(
    magic: [u8; 4],
    out: &mut [u8],
    mut emit: impl FnMut(&mut SectionWriter<'_>) -> Result<D, BlobError>,
) -> Result<usize, BlobError> {
    let mut measure = SectionWriter::new(None);
    let descriptor = emit(&mut measure)?;
    let desc_len = descriptor_len(&descriptor)?;
    let start = data_start(desc_len).ok_or(BlobError::TooLarge)?;
    let total = start.checked_add(measure.end).ok_or(BlobError::TooLarge)?;
    let blob = out.get_mut(..total).ok_or(BlobError::BufferTooSmall)?;
    blob.fill(0);
    let desc_area = blob
        .get_mut(HEADER_LEN..HEADER_LEN + desc_len)
        .ok_or(BlobError::BufferTooSmall)?;
    postcard::to_slice(&descriptor, desc_area).map_err(|_| BlobError::Encode)?;
    let mut writer = SectionWriter::new(blob.get_mut(start..));
    emit(&mut writer)?;
    seal(blob, magic, desc_len)?;
    Ok(total)
}

/// Fills the header of `blob` (the whole blob, descriptor and data already in place): `magic`,
/// [`FORMAT_VERSION`], reserved 0, total length `blob.len()`, the payload CRC-32 and the
/// descriptor length.
fn seal(blob: &mut [u8], magic: [u8; 4], desc_len: usize) -> Result<(), BlobError> {
    let crc = crc32(blob.get(HEADER_LEN..).ok_or(BlobError::BufferTooSmall)?);
    let total_u32 = u32::try_from(blob.len()).map_err(|_| BlobError::TooLarge)?;
    let desc_u32 = u32::try_from(desc_len).map_err(|_| BlobError::TooLarge)?;
    let header = blob
        .get_mut(..HEADER_LEN)
        .ok_or(BlobError::BufferTooSmall)?;
    let mut fields = [0_u8; HEADER_LEN];
    for (slot, byte) in fields.iter_mut().zip(
        magic
            .iter()
            .chain(&FORMAT_VERSION.to_le_bytes())
            .chain(&0_u16.to_le_bytes())
            .chain(&total_u32.to_le_bytes())
            .chain(&crc.to_le_bytes())
            .chain(&desc_u32.to_le_bytes()),
    ) {
        *slot = *byte;
    }
    header.copy_from_slice(&fields);
    Ok(())
}
