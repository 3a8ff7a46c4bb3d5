//! Weights packed for the hosts' dot-product instructions: a second copy of a layer's int8
//! weights, made once when a host network is built, in the order in which `vpdpbusd` (x86
//! AVX-VNNI and AVX-512 VNNI) consumes them with one broadcast input word per step, so that one
//! instruction adds four columns to sixteen rows at once and no horizontal reduction is left at
//! the end of a row (`kernels::x86::packed`).
//!
//! Layout: rows in blocks of [`PACK_ROWS`] (the last block padded with zero rows), each block the
//! groups of four columns in order (the last group padded with zero columns), each group 64
//! bytes, row `r` of the block at bytes `4 r .. 4 r + 4`, holding
//! - [`PackedKind::Bytes`] (int8 inputs): the four weights made unsigned, `w ^ 0x80 = w + 128`
//!   (the kernel subtracts `128 sum x` once per layer);
//! - [`PackedKind::Words`] (int16 inputs): the four weights as they are, and after the groups
//!   each row's weight sum (sixteen little-endian int32): the kernel splits every input into its
//!   high byte `h` and unsigned low byte `l`, `x = 256 h + l`, and sums `w l` and
//!   `w (h + 128)` with the same bytes, then subtracts `256 * 128 sum w`.
//!
//! Layers wider than [`MAX_PACKED_COLUMNS`] are not packed (the kernels keep a layer's input
//! words on the stack). A [`PackedWeights`] is only made by checking its bytes against the
//! layer's weights ([`PackedWeights::new`]), and the kernels use it only with that very weight
//! slice, so a packed copy can never stand for other weights. The results are those of the
//! row-major kernels bit for bit (wrapping int32 sums: the order of the products does not
//! matter).

use super::{Accumulator, FullyConnected, KernelError, LayerInput};

/// Rows per packed block (one 512-bit register, or two 256-bit ones, of int32 sums).
pub const PACK_ROWS: usize = 16;

/// Columns per group.
pub const GROUP_COLUMNS: usize = 4;

/// Bytes of one group of columns in a block: four bytes for each of [`PACK_ROWS`] rows.
pub const GROUP_BYTES: usize = GROUP_COLUMNS * PACK_ROWS;

/// Widest layer that is packed.
pub const MAX_PACKED_COLUMNS: usize = 1024;

/// The input type a packed copy is made for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PackedKind {
    /// int8 inputs: weights made unsigned.
    Bytes,
    /// int16 inputs: signed weights and each row's weight sum.
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

    /// Bytes of one block of rows of a layer `in_features` wide (`None` beyond
    /// [`MAX_PACKED_COLUMNS`] or for no columns).
    pub fn block_len(self, in_features: usize) -> Option<usize> {
        if in_features == 0 || in_features > MAX_PACKED_COLUMNS {
            return None;
        }
        let groups = in_features.div_ceil(GROUP_COLUMNS) * GROUP_BYTES;
        Some(match self {
            Self::Bytes => groups,
            Self::Words => groups + 4 * PACK_ROWS,
        })
    }

    /// The packed length of a `[out_features, in_features]` layer, `None` where it is not
    /// packed ([`Self::block_len`]) or on overflow.
    pub fn packed_len(self, in_features: usize, out_features: usize) -> Option<usize> {
        out_features
            .div_ceil(PACK_ROWS)
            .checked_mul(self.block_len(in_features)?)
    }

    /// The packed bytes of `layer`, in order.
    fn bytes<'a, A>(self, layer: &'a FullyConnected<'_, A>) -> impl Iterator<Item = u8> + 'a {
        let (width, height) = (layer.in_features, layer.out_features);
        let weight = move |row: usize, column: usize| {
            let inside = row < height && column < width;
            let index = row.wrapping_mul(width).wrapping_add(column);
            inside
                .then(|| layer.weights.get(index).copied())
                .flatten()
                .unwrap_or(0)
        };
        let groups = width.div_ceil(GROUP_COLUMNS);
        (0..height.div_ceil(PACK_ROWS)).flat_map(move |block| {
            let rows = move || (0..PACK_ROWS).map(move |r| block * PACK_ROWS + r);
            let weights = (0..groups).flat_map(move |group| {
                rows().flat_map(move |row| {
                    let first = group * GROUP_COLUMNS;
                    let word: [u8; GROUP_COLUMNS] = core::array::from_fn(|k| {
                        let w = weight(row, first + k) as u8;
                        match self {
                            Self::Bytes => w ^ 0x80,
                            Self::Words => w,
                        }
                    });
                    word.into_iter()
                })
            });
            let sums = rows()
                .filter(move |_| self == Self::Words)
                .flat_map(move |row| {
                    let sum: i32 = (0..width).map(|c| i32::from(weight(row, c))).sum();
                    sum.to_le_bytes().into_iter()
                });
            weights.chain(sums)
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
        // 3 x 5: one block of two groups (columns 4 and the padding).
        let weights: [i8; 15] = core::array::from_fn(|i| (i as i8 - 7) * 9);
        let bias = [0_i32; 3];
        let layer = FullyConnected::new(5, 3, &weights, &bias);
        for kind in [PackedKind::Bytes, PackedKind::Words] {
            let len = kind.packed_len(5, 3).unwrap();
            let sums_len = if kind == PackedKind::Words { 64 } else { 0 };
            assert_eq!(len, 2 * GROUP_BYTES + sums_len);
            let mut out = [0_u8; 4 * GROUP_BYTES];
            pack(&layer, kind, &mut out[..len]).unwrap();
            for row in 0..PACK_ROWS {
                let w = |column: usize| {
                    if row < 3 && column < 5 {
                        weights[row * 5 + column]
                    } else {
                        0
                    }
                };
                for column in 0..8 {
                    let at = column / 4 * GROUP_BYTES + 4 * row + column % 4;
                    let stored = match kind {
                        PackedKind::Bytes => (out[at] ^ 0x80) as i8,
                        PackedKind::Words => out[at] as i8,
                    };
                    assert_eq!(stored, w(column), "{kind:?} row {row} column {column}");
                }
                if kind == PackedKind::Words {
                    let at = 2 * GROUP_BYTES + 4 * row;
                    let sum = i32::from_le_bytes([out[at], out[at + 1], out[at + 2], out[at + 3]]);
                    assert_eq!(sum, (0..5).map(|c| i32::from(w(c))).sum::<i32>());
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
            bad[len - 1] ^= 1;
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
        // Too wide to pack.
        assert_eq!(
            PackedKind::Bytes.packed_len(MAX_PACKED_COLUMNS + 1, 1),
            None
        );
    }

    fn kind_input<'a>(kind: PackedKind, x8: &'a [i8], x16: &'a [i16]) -> LayerInput<'a> {
        match kind {
            PackedKind::Bytes => LayerInput::Int8(x8),
            PackedKind::Words => LayerInput::Int16(x16),
        }
    }
}
