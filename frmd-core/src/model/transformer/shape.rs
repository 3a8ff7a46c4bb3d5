//! Sizes of a transformer backbone and the scratch memory its forward passes need.

use super::{ScratchBuffer, TransformerError};

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
    /// int8 values.
    pub bytes: usize,
    /// int32 values.
    pub accumulators: usize,
}

impl ScratchLens {
    /// Total RAM in bytes (`4 floats + bytes + 4 accumulators`, saturating).
    pub const fn ram_bytes(&self) -> usize {
        self.floats
            .saturating_mul(4)
            .saturating_add(self.bytes)
            .saturating_add(self.accumulators.saturating_mul(4))
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
            bytes: 0,
            accumulators: 0,
        }
    }

    /// Scratch needed by the int8 form: floats `TW + 2T hd + 2hd + T + W` (residual, one
    /// head's keys and values, one query, one head output, one score row, one token row); bytes
    /// `max(2TW + 4W, cond_dim, k)` (quantized LN1 outputs, quantized attention outputs, the
    /// feed-forward hidden row); accumulators `max(W, output)`. Saturates on overflow.
    pub const fn int8_scratch(&self) -> ScratchLens {
        let tw = self.token_values();
        let hd = self.head_dim();
        let floats = tw
            .saturating_add(self.tokens().saturating_mul(hd).saturating_mul(2))
            .saturating_add(hd.saturating_mul(2))
            .saturating_add(self.tokens())
            .saturating_add(self.width);
        let bytes = tw.saturating_mul(2).saturating_add(self.hidden());
        ScratchLens {
            floats,
            bytes: max(bytes, max(self.cond_dim, self.action_dim)),
            accumulators: max(self.width, self.output),
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
/// [`TransformerShape::int8_scratch`] elements in each buffer (longer is fine).
#[derive(Debug)]
pub struct TransformerBuffers<'s> {
    /// f32 values.
    pub floats: &'s mut [f32],
    /// int8 values.
    pub bytes: &'s mut [i8],
    /// int32 values.
    pub accumulators: &'s mut [i32],
}

/// [`TransformerBuffers`] as fixed arrays, sized by `const` lengths from
/// [`TransformerShape::f32_scratch`] / [`TransformerShape::int8_scratch`] (longer is fine):
///
/// ```
/// use frmd_core::model::transformer::{ScratchLens, TransformerScratch, TransformerShape};
/// const SHAPE: TransformerShape = TransformerShape {
///     horizon: 12, action_dim: 7, cond_dim: 54, width: 128, heads: 2, layers: 3, output: 77,
/// };
/// const LENS: ScratchLens = SHAPE.int8_scratch();
/// type Scratch = TransformerScratch<{ LENS.floats }, { LENS.bytes }, { LENS.accumulators }>;
/// let scratch = Scratch::new();
/// assert_eq!(LENS.ram_bytes(), 20_024);
/// # let _ = scratch;
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct TransformerScratch<const FLOATS: usize, const BYTES: usize, const ACCUMULATORS: usize> {
    floats: [f32; FLOATS],
    bytes: [i8; BYTES],
    accumulators: [i32; ACCUMULATORS],
}

impl<const FLOATS: usize, const BYTES: usize, const ACCUMULATORS: usize>
    TransformerScratch<FLOATS, BYTES, ACCUMULATORS>
{
    /// Zeroed scratch.
    pub const fn new() -> Self {
        Self {
            floats: [0.0; FLOATS],
            bytes: [0; BYTES],
            accumulators: [0; ACCUMULATORS],
        }
    }

    /// The arrays as [`TransformerBuffers`].
    pub fn buffers(&mut self) -> TransformerBuffers<'_> {
        TransformerBuffers {
            floats: &mut self.floats,
            bytes: &mut self.bytes,
            accumulators: &mut self.accumulators,
        }
    }
}

impl<const FLOATS: usize, const BYTES: usize, const ACCUMULATORS: usize> Default
    for TransformerScratch<FLOATS, BYTES, ACCUMULATORS>
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
