//! Sizes of a transformer backbone and the scratch memory its forward passes need.

use super::{ScratchBuffer, TransformerError};
use crate::kernels::{Accumulator, Precision};

/// Sizes of a transformer backbone.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TransformerShape {
    /// `n`: number of trajectory-step tokens.
    pub horizon: usize,
    /// `k`: values per trajectory step (`traj_in` input width).
    pub action_dim: usize,
    /// Length of the condition vector `[obs history, y0, v0 * control_dt]` (`cond_in` input).
    pub cond_dim: usize,
    /// Token width `W`.
    pub width: usize,
    /// Attention heads; must divide `width`.
    pub heads: usize,
    /// Number of blocks `L`.
    pub layers: usize,
    /// Width of the head's output.
    pub output: usize,
}

/// Scratch lengths (in elements) one forward pass needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScratchLens {
    /// f32 values.
    pub floats: usize,
    /// Activation codes (int8 or int16).
    pub codes: usize,
    /// Accumulators (int32 or int64).
    pub accumulators: usize,
    /// Bytes per code (1 or 2).
    pub code_bytes: usize,
    /// Bytes per accumulator (4 or 8).
    pub accumulator_bytes: usize,
}

impl ScratchLens {
    /// Total RAM in bytes (`4 floats + code_bytes codes + accumulator_bytes accumulators`,
    /// saturating).
    pub const fn ram_bytes(&self) -> usize {
        self.floats
            .saturating_mul(4)
            .saturating_add(self.codes.saturating_mul(self.code_bytes))
            .saturating_add(self.accumulators.saturating_mul(self.accumulator_bytes))
    }
}

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

impl TransformerShape {
    /// `T = horizon + 2` tokens.
    pub const fn tokens(&self) -> usize {
        self.horizon.saturating_add(2)
    }

    /// `W / heads` (0 if `heads == 0`).
    pub const fn head_dim(&self) -> usize {
        match self.width.checked_div(self.heads) {
            Some(d) => d,
            None => 0,
        }
    }

    /// Feed-forward hidden width `4 W`.
    pub const fn hidden(&self) -> usize {
        self.width.saturating_mul(4)
    }

    /// `n k`: length of the trajectory input.
    pub const fn trajectory_len(&self) -> usize {
        self.horizon.saturating_mul(self.action_dim)
    }

    /// `T W`: length of the token matrix (and of the head's input).
    pub const fn token_values(&self) -> usize {
        self.tokens().saturating_mul(self.width)
    }

    /// Scratch needed by the f32 form: `3TW + 2T hd + hd + T + 5W` floats (residual, LN1
    /// outputs, attention outputs, one head's keys and values, one query, one score row, the
    /// feed-forward hidden row and one token row). Saturates on overflow (then
    /// [`TransformerShape::validate`] fails).
    pub const fn f32_scratch(&self) -> ScratchLens {
        let tw = self.token_values();
        let hd = self.head_dim();
        let floats = tw
            .saturating_mul(3)
            .saturating_add(self.tokens().saturating_mul(hd).saturating_mul(2))
            .saturating_add(hd)
            .saturating_add(self.tokens())
            .saturating_add(self.width.saturating_mul(5));
        ScratchLens {
            floats,
            codes: 0,
            accumulators: 0,
            code_bytes: 1,
            accumulator_bytes: 4,
        }
    }

    /// Scratch needed by the int8 form ([`Self::quantized_scratch`] of `i8`).
    pub const fn int8_scratch(&self) -> ScratchLens {
        self.quantized_scratch::<i8>()
    }

    /// Scratch needed by the int16-activation form ([`Self::quantized_scratch`] of `i16`).
    pub const fn int16_scratch(&self) -> ScratchLens {
        self.quantized_scratch::<i16>()
    }

    /// Scratch needed by the quantized form with `P` activations: floats
    /// `TW + 2T hd + 2hd + T + W` (residual, one head's keys and values, one query, one head
    /// output, one score row, one token row); codes `max(2TW + 4W, cond_dim, k)` (quantized LN1
    /// outputs, quantized attention outputs, the feed-forward hidden row); accumulators
    /// `max(W, output)`. The same counts for both precisions; int16 codes and int64 accumulators
    /// take twice the bytes. Saturates on overflow.
    pub const fn quantized_scratch<P: Precision>(&self) -> ScratchLens {
        let tw = self.token_values();
        let hd = self.head_dim();
        let floats = tw
            .saturating_add(self.tokens().saturating_mul(hd).saturating_mul(2))
            .saturating_add(hd.saturating_mul(2))
            .saturating_add(self.tokens())
            .saturating_add(self.width);
        let codes = tw.saturating_mul(2).saturating_add(self.hidden());
        ScratchLens {
            floats,
            codes: max(codes, max(self.cond_dim, self.action_dim)),
            accumulators: max(self.width, self.output),
            code_bytes: core::mem::size_of::<P>(),
            accumulator_bytes: core::mem::size_of::<P::Acc>(),
        }
    }

    /// Checks that every size is positive, `heads` divides `width` and no derived size overflows.
    pub fn validate(&self) -> Result<(), TransformerError> {
        let sizes = [
            self.horizon,
            self.action_dim,
            self.cond_dim,
            self.width,
            self.heads,
            self.layers,
            self.output,
        ];
        if sizes.contains(&0) {
            return Err(TransformerError::ZeroSize);
        }
        if !self.width.is_multiple_of(self.heads) {
            return Err(TransformerError::HeadsDoNotDivideWidth);
        }
        // Largest products the forward passes form: the head's weights (T W output), fc1's
        // weights (4 W W), the scratch (below 32 T W elements), the input layers' weights.
        let token_values = self
            .horizon
            .checked_add(2)
            .and_then(|t| t.checked_mul(self.width));
        let products = [
            token_values.and_then(|tw| tw.checked_mul(self.output)),
            token_values.and_then(|tw| tw.checked_mul(32)),
            self.width
                .checked_mul(self.width)
                .and_then(|ww| ww.checked_mul(4)),
            self.horizon.checked_mul(self.action_dim),
            self.cond_dim.checked_mul(self.width),
            self.action_dim.checked_mul(self.width),
        ];
        if products.iter().any(Option::is_none) {
            return Err(TransformerError::SizeOverflow);
        }
        Ok(())
    }
}

/// Scratch of a forward pass, borrowed: at least [`TransformerShape::f32_scratch`] /
/// [`TransformerShape::quantized_scratch`] elements in each buffer (longer is fine), with `P`
/// codes (int8, the default, or int16) and their accumulators.
#[derive(Debug)]
pub struct TransformerBuffers<'s, P: Precision = i8> {
    /// f32 values.
    pub floats: &'s mut [f32],
    /// Activation codes.
    pub codes: &'s mut [P],
    /// Accumulators.
    pub accumulators: &'s mut [P::Acc],
}

/// [`TransformerBuffers`] as fixed arrays, sized by `const` lengths from
/// [`TransformerShape::f32_scratch`] / [`TransformerShape::quantized_scratch`] (longer is fine):
///
/// ```
/// use frmd_core::model::transformer::{ScratchLens, TransformerScratch, TransformerShape};
/// const SHAPE: TransformerShape = TransformerShape {
///     horizon: 12, action_dim: 7, cond_dim: 54, width: 128, heads: 2, layers: 3, output: 77,
/// };
/// const LENS: ScratchLens = SHAPE.int8_scratch();
/// type Scratch = TransformerScratch<{ LENS.floats }, { LENS.codes }, { LENS.accumulators }>;
/// let scratch = Scratch::new();
/// assert_eq!(LENS.ram_bytes(), 20_024);
/// // int16 activations: the same counts, twice the bytes for codes and accumulators.
/// const LENS16: ScratchLens = SHAPE.int16_scratch();
/// type Scratch16 =
///     TransformerScratch<{ LENS16.floats }, { LENS16.codes }, { LENS16.accumulators }, i16>;
/// let scratch16 = Scratch16::new();
/// assert_eq!(LENS16.ram_bytes(), 24_632);
/// # let _ = (scratch, scratch16);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct TransformerScratch<
    const FLOATS: usize,
    const CODES: usize,
    const ACCUMULATORS: usize,
    P: Precision = i8,
> {
    floats: [f32; FLOATS],
    codes: [P; CODES],
    accumulators: [P::Acc; ACCUMULATORS],
}

impl<const FLOATS: usize, const CODES: usize, const ACCUMULATORS: usize, P: Precision>
    TransformerScratch<FLOATS, CODES, ACCUMULATORS, P>
{
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            floats: [0.0; FLOATS],
            codes: [P::ZERO; CODES],
            accumulators: [<P::Acc as Accumulator>::ZERO; ACCUMULATORS],
        }
    }

    /// The arrays as [`TransformerBuffers`].
    pub fn buffers(&mut self) -> TransformerBuffers<'_, P> {
        TransformerBuffers {
            floats: &mut self.floats,
            codes: &mut self.codes,
            accumulators: &mut self.accumulators,
        }
    }
}

impl<const FLOATS: usize, const CODES: usize, const ACCUMULATORS: usize, P: Precision> Default
    for TransformerScratch<FLOATS, CODES, ACCUMULATORS, P>
{
    fn default() -> Self {
        Self::new()
    }
}

/// Splits the first `len` elements off `rest`.
pub(super) fn take<'s, T>(
    rest: &mut &'s mut [T],
    len: usize,
    buffer: ScratchBuffer,
) -> Result<&'s mut [T], TransformerError> {
    let all = core::mem::take(rest);
    let needed = len;
    let (head, tail) = all
        .split_at_mut_checked(len)
        .ok_or(TransformerError::ScratchTooSmall { buffer, needed })?;
    *rest = tail;
    Ok(head)
}

/// The first `needed` elements of `buffer`, or [`TransformerError::ScratchTooSmall`].
pub(super) fn prefix<T>(
    values: &mut [T],
    needed: usize,
    buffer: ScratchBuffer,
) -> Result<&mut [T], TransformerError> {
    values
        .get_mut(..needed)
        .ok_or(TransformerError::ScratchTooSmall { buffer, needed })
}
