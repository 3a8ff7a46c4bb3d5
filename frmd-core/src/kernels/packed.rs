//! Weights packed for the hosts' dot-product instructions: a second copy of a layer's int8
//! weights, made once when a host network is built, in the order in which `vpdpbusd` /
//! `vpdpwssd` (x86 AVX-VNNI and AVX-512 VNNI) consume them with one broadcast input word per
//! step, so that one instruction adds a group of columns to sixteen rows at once and no
//! horizontal reduction is left at the end of a row (`kernels::x86::packed`).
//!
//! Layout: rows in blocks of [`PACK_ROWS`] (the last block padded with zero rows), each block the
//! groups of columns in order (the last group padded with zero columns), each group 64 bytes: row
//! `r` of the block at bytes `4 r .. 4 r + 4`, holding
//! - [`PackedKind::Bytes`] (int8 inputs): the four weights of columns `4 g .. 4 g + 4` made
//!   unsigned, `w ^ 0x80 = w + 128` (the kernel subtracts `128 sum x` once per layer);
//! - [`PackedKind::Words`] (int16 inputs): the two weights of columns `2 g, 2 g + 1`
//!   sign-extended to little-endian int16.
//!
//! A [`PackedWeights`] is only made by checking its bytes against the layer's weights
//! ([`PackedWeights::new`]), and the kernels use it only with that very weight slice, so a
//! packed copy can never stand for other weights. The results are those of the row-major kernels
//! bit for bit (wrapping int32 sums: the order of the products does not matter).

use super::{Accumulator, FullyConnected, KernelError, LayerInput};

/// Rows per packed block (one 512-bit register, or two 256-bit ones, of int32 sums).
pub const PACK_ROWS: usize = 16;

/// Bytes of one group of columns in a block: four bytes for each of [`PACK_ROWS`] rows.
pub const GROUP_BYTES: usize = 4 * PACK_ROWS;

/// The input type a packed copy is made for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PackedKind {
    /// int8 inputs: four columns per group, weights made unsigned.
    Bytes,
    /// int16 inputs: two columns per group, weights widened to int16.
    Words,
}

impl PackedKind {
    /// The kind for `input`'s type.
    pub fn of(input: LayerInput<'_>) -> Self {
        match input {
            LayerInput::Int8(_) => Self::Bytes,
            LayerInput::Int16(_) => Self::Words,
        }
    }

    /// Columns per group.
    pub const fn columns(self) -> usize {
        match self {
            Self::Bytes => 4,
            Self::Words => 2,
        }
    }

    /// The packed length of a `[out_features, in_features]` layer, `None` on overflow.
    pub fn packed_len(self, in_features: usize, out_features: usize) -> Option<usize> {
        let groups = in_features.div_ceil(self.columns());
        out_features
            .div_ceil(PACK_ROWS)
            .checked_mul(groups)?
            .checked_mul(GROUP_BYTES)
    }

    /// The packed bytes of `layer`, in order.
    fn bytes<'a, A>(self, layer: &'a FullyConnected<'_, A>) -> impl Iterator<Item = u8> + 'a {
        let (width, height) = (layer.in_features, layer.out_features);
        let columns = self.columns();
        let weight = move |row: usize, column: usize| {
            let inside = row < height && column < width;
            let index = row.wrapping_mul(width).wrapping_add(column);
            inside
                .then(|| layer.weights.get(index).copied())
                .flatten()
                .unwrap_or(0)
        };
        let groups = width.div_ceil(columns);
        (0..height.div_ceil(PACK_ROWS)).flat_map(move |block| {
            (0..groups).flat_map(move |group| {
                (0..PACK_ROWS).flat_map(move |r| {
                    let row = block * PACK_ROWS + r;
                    let first = group * columns;
                    let word = match self {
                        Self::Bytes => {
                            core::array::from_fn(|k| (weight(row, first + k) as u8) ^ 0x80)
                        }
                        Self::Words => {
                            let [a, b] = [0, 1].map(|k| i16::from(weight(row, first + k)));
                            let ([a0, a1], [b0, b1]) = (a.to_le_bytes(), b.to_le_bytes());
                            [a0, a1, b0, b1]
                        }
                    };
                    word.into_iter()
                })
            })
        })
    }
}

/// Writes the packed copy of `layer` for inputs of `kind` into `out` (of exactly
/// [`PackedKind::packed_len`] bytes).
pub fn pack<A>(
    layer: &FullyConnected<'_, A>,
    kind: PackedKind,
    out: &mut [u8],
) -> Result<(), KernelError> {
    let expected = kind.packed_len(layer.in_features, layer.out_features);
    if expected != Some(out.len()) {
        return Err(KernelError::OutputLength);
    }
    for (slot, byte) in out.iter_mut().zip(kind.bytes(layer)) {
        *slot = byte;
    }
    Ok(())
}

/// Whether this CPU's kernels run packed weights (x86-64 with AVX-VNNI or AVX-512 VNNI, those
/// paths enabled): a host packs its networks only then ([`pack`] costs a second copy of the
/// weights).
pub fn runs_here() -> bool {
    #[cfg(target_arch = "x86_64")]
    if let Some(token) = super::x86::Avx2::get() {
        return token.runs_packed();
    }
    false
}

/// A layer's weights in the packed layout, checked against them: what
/// [`FullyConnected::packed`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackedWeights<'a> {
    bytes: &'a [u8],
    kind: PackedKind,
    /// The weight slice the bytes were checked against (address and length; only compared).
    source: (usize, usize),
    in_features: usize,
    out_features: usize,
}

impl<'a> PackedWeights<'a> {
    /// Views `bytes` as the packed copy of `layer`'s weights for inputs of `kind`, after
    /// checking every byte against what [`pack`] writes (`KernelError::WeightsLength` if the
    /// length or any byte differs, or the layer's own shape is inconsistent).
    pub fn new<A: Accumulator>(
        layer: &FullyConnected<'_, A>,
        kind: PackedKind,
        bytes: &'a [u8],
    ) -> Result<Self, KernelError> {
        layer.validate()?;
        let expected = kind.packed_len(layer.in_features, layer.out_features);
        // Folded without early exit, once per layer when a network is built.
        let same = expected == Some(bytes.len())
            && bytes
                .iter()
                .zip(kind.bytes(layer))
                .fold(true, |same, (a, b)| same & (*a == b));
        if !same {
            return Err(KernelError::WeightsLength);
        }
        Ok(Self {
            bytes,
            kind,
            source: (layer.weights.as_ptr() as usize, layer.weights.len()),
            in_features: layer.in_features,
            out_features: layer.out_features,
        })
    }

    /// The input type the copy is for.
    pub fn kind(&self) -> PackedKind {
        self.kind
    }

    /// The packed bytes, [`PACK_ROWS`] rows per block.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Input width of the layer.
    pub fn in_features(&self) -> usize {
        self.in_features
    }

    /// Whether this is the packed copy of `layer`'s very weights for `input`'s type.
    pub(crate) fn serves<A>(&self, layer: &FullyConnected<'_, A>, input: LayerInput<'_>) -> bool {
        let source = (layer.weights.as_ptr() as usize, layer.weights.len());
        self.source == source
            && (self.in_features, self.out_features) == (layer.in_features, layer.out_features)
            && self.kind == PackedKind::of(input)
            && input.len() == self.in_features
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_bytes_follow_the_layout_and_are_checked() {
        // 3 x 5: one block, two byte groups (columns 4 and the padding) or three word groups.
        let weights: [i8; 15] = core::array::from_fn(|i| (i as i8 - 7) * 9);
        let bias = [0_i32; 3];
        let layer = FullyConnected::new(5, 3, &weights, &bias);
        for kind in [PackedKind::Bytes, PackedKind::Words] {
            let len = kind.packed_len(5, 3).unwrap();
            assert_eq!(len, 5_usize.div_ceil(kind.columns()) * GROUP_BYTES);
            let mut out = [0_u8; 4 * GROUP_BYTES];
            pack(&layer, kind, &mut out[..len]).unwrap();
            for row in 0..PACK_ROWS {
                for column in 0..5_usize.div_ceil(kind.columns()) * kind.columns() {
                    let w = if row < 3 && column < 5 {
                        weights[row * 5 + column]
                    } else {
                        0
                    };
                    let (group, k) = (column / kind.columns(), column % kind.columns());
                    let at = group * GROUP_BYTES + 4 * row;
                    let stored = match kind {
                        PackedKind::Bytes => (out[at + k] ^ 0x80) as i8,
                        PackedKind::Words => {
                            i16::from_le_bytes([out[at + 2 * k], out[at + 2 * k + 1]]) as i8
                        }
                    };
                    assert_eq!(stored, w, "{kind:?} row {row} column {column}");
                }
            }
            let packed = PackedWeights::new(&layer, kind, &out[..len]).unwrap();
            assert!(packed.serves(&layer, kind_input(kind, &[0; 5], &[0; 5])));
            assert!(!packed.serves(&layer, kind_input(kind, &[0; 4], &[0; 4])));
            let other = FullyConnected::new(5, 3, &weights[..], &bias);
            let copy: [i8; 15] = weights;
            let elsewhere = FullyConnected::new(5, 3, &copy, &bias);
            assert!(packed.serves(&other, kind_input(kind, &[0; 5], &[0; 5])));
            assert!(!packed.serves(&elsewhere, kind_input(kind, &[0; 5], &[0; 5])));
            // One changed byte, or a wrong length, is refused.
            let mut bad = out;
            bad[7] ^= 1;
            assert_eq!(
                PackedWeights::new(&layer, kind, &bad[..len]),
                Err(KernelError::WeightsLength)
            );
            assert_eq!(
                PackedWeights::new(&layer, kind, &out[..len - 1]),
                Err(KernelError::WeightsLength)
            );
            assert_eq!(
                pack(&layer, kind, &mut out[..len + 1]),
                Err(KernelError::OutputLength)
            );
        }
    }

    fn kind_input<'a>(kind: PackedKind, x8: &'a [i8], x16: &'a [i16]) -> LayerInput<'a> {
        match kind {
            PackedKind::Bytes => LayerInput::Int8(x8),
            PackedKind::Words => LayerInput::Int16(x16),
        }
    }
}
