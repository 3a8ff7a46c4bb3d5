//! Standard normal samples from 32 random bits, integer-only and table-driven: the same bits on
//! every target and the same instructions for every draw (no rejection loop, no branch on the
//! value).
//!
//! The top bit is the sign. The other 31 bits `m` stand for the tail probability
//! `p = m / 2^31` of `|z|`, so `|z| = Q(p) = Phi^-1(1 - p/2)`. The leading zeros of `m` give the
//! octave `k` of `p` (`p` in `[2^-(k+1), 2^-k)`), the next 4 bits one of 16 equal segments of it
//! and the following 15 bits the position inside the segment; `|z|` is interpolated linearly
//! between the segment's ends, read from a table of `26 x 17` values of `Q` in units of `2^-20`
//! ([`super::normal_table`]). Octaves below `2^-26` (probability `2^-26` in all) take the last
//! table value, so `|z| <= Q(2^-26) = 5.663`. The interpolation is within `2e-4` of `Q` everywhere;
//! the sample is `z` in units of `2^-20`, converted exactly to f32.
//!
//! Cost on a Cortex-M4: one `CLZ`, a few shifts and masks, two table loads, one multiply; about 40
//! instructions with the 32-bit draw, against about 1 200 for a Box-Muller pair in software f32.

use super::normal_table::{OCTAVES, SEGMENTS, TABLE};

/// Fraction bits of the position inside a segment.
const FRACTION_BITS: u32 = 15;
/// `2^-20`: the unit of the table and of [`normal_q20`].
pub(super) const Z_UNIT: f32 = 1.0 / 1_048_576.0;

/// A standard normal sample from the random bits `bits`, in units of `2^-20` (`|z| < 5.67`).
#[inline]
pub fn normal_q20(bits: u32) -> i32 {
    let negative = 0_i32.wrapping_sub((bits >> 31) as i32);
    let m = bits & 0x7FFF_FFFF;
    let octave = leading_zeros(m).wrapping_sub(1) as i32;
    // min(octave, OCTAVES - 1) without a branch.
    let over = octave - (OCTAVES as i32 - 1);
    let octave = (octave - (over & !(over >> 31))) as u32;
    // Offset of m in its octave (0 for the clamped octaves below the table).
    let offset = m.wrapping_sub(1 << (30 - octave)) as i32;
    let offset = (offset & !(offset >> 31)) as u32;
    // The offset as a 31-bit fraction of the octave: 4 segment bits, then the position.
    let position = offset << (octave + 1);
    let segment = (position >> 27) as usize;
    let fraction = ((position >> (27 - FRACTION_BITS)) & ((1 << FRACTION_BITS) - 1)) as i32;
    let index = octave as usize * (SEGMENTS + 1) + segment;
    let start = TABLE.get(index).copied().unwrap_or(0);
    let end = TABLE.get(index + 1).copied().unwrap_or(0);
    let magnitude = start + (((end - start) * fraction) >> FRACTION_BITS);
    (magnitude ^ negative) - negative
}

/// Leading zeros of `x`: the `CLZ` instruction where the core has one, else a branch-free
/// binary search (Armv6-M and Armv8-M Baseline have no `CLZ`, and the library routine branches
/// on the value).
#[inline(always)]
fn leading_zeros(x: u32) -> u32 {
    #[cfg(not(frmd_no_clz))]
    {
        x.leading_zeros()
    }
    #[cfg(frmd_no_clz)]
    {
        leading_zeros_branch_free(x)
    }
}

/// `x.leading_zeros()` by five steps of "if the top half of what is left is zero, count it and
/// shift it out", each step an arithmetic mask instead of a branch.
#[cfg_attr(not(any(frmd_no_clz, test)), allow(dead_code))]
#[inline(always)]
fn leading_zeros_branch_free(mut x: u32) -> u32 {
    let mut count = 0;
    for bits in [16_u32, 8, 4, 2, 1] {
        // `bits` when the top `bits` bits of `x` are zero, else 0.
        let step = ((x >> (32 - bits)).wrapping_sub(1) >> 31) * bits;
        count += step;
        x <<= step;
    }
    count + ((x >> 31) ^ 1)
}

#[cfg(test)]
mod tests;
