//! Wide-integer model (tests and the `reference` feature) of requantization, written directly from the formulas in
//! `quant::fixed_point` with i128 arithmetic and floor divisions (no masks, no nudges), so it
//! shares no code path with the implementation.

/// Edge multipliers of the requantization checks: zero, one, the ends of the normalized Q31
/// mantissa range and a value inside it.
pub const EDGE_MULTIPLIERS: [i32; 7] = [
    0,
    1,
    super::Q31_MANTISSA_MIN,
    super::Q31_MANTISSA_MIN + 1,
    1_518_500_250,
    i32::MAX - 1,
    i32::MAX,
];

/// Output zero points at and next to the ends of the int8 range and around zero.
pub const EDGE_ZERO_POINTS: [i32; 7] = [-128, -127, -1, 0, 1, 126, 127];

/// Activation clamps: the full range, ReLU, single values at both ends, a narrow window.
pub const EDGE_CLAMPS: [(i8, i8); 5] = [(-128, 127), (0, 127), (-128, -128), (127, 127), (-5, 6)];

/// Number of [`edge_accumulators`].
pub const EDGE_ACCUMULATORS: usize = 7 + 31 * 6;

/// Interesting accumulators: the ends of the range, then the values around each power of two.
pub fn edge_accumulators() -> [i32; EDGE_ACCUMULATORS] {
    let mut values = [0; EDGE_ACCUMULATORS];
    let ends = [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
    let (head, powers) = values.split_at_mut(ends.len());
    head.copy_from_slice(&ends);
    for (e, slot) in powers.chunks_exact_mut(6).enumerate() {
        let p = 1_i32 << e;
        slot.copy_from_slice(&[p, p - 1, p + 1, -p, -p + 1, -p - 1]);
    }
    values
}

/// `floor((a * b + 2^30) / 2^31)` saturated to i32: round half up of `a * b / 2^31`.
pub fn high_mul(a: i32, b: i32) -> i32 {
    let product = i128::from(a) * i128::from(b);
    let rounded = (product + (1_i128 << 30)).div_euclid(1_i128 << 31);
    saturate(rounded)
}

/// `sign(x) * floor((|x| + 2^(e-1)) / 2^e)`: round half away from zero of `x / 2^e`.
pub fn divide_pot(x: i32, exponent: u32) -> i32 {
    if exponent == 0 {
        return x;
    }
    // Beyond 2^64 every quotient rounds to 0; capping keeps the shift defined.
    let exponent = exponent.min(64);
    let magnitude = i128::from(x).abs();
    let divisor = 1_i128 << exponent;
    let rounded = (2 * magnitude + divisor).div_euclid(2 * divisor);
    saturate(if x < 0 { -rounded } else { rounded })
}

/// Left shift by `max(shift, 0)` saturated, high multiply, then divide by `2^max(-shift, 0)`.
pub fn scale(acc: i32, multiplier: i32, shift: i32) -> i32 {
    let left = shift.max(0) as u32;
    let right = (-i64::from(shift)).max(0) as u32;
    let shifted = saturate(i128::from(acc) << left.min(40));
    divide_pot(high_mul(shifted, multiplier), right)
}

/// `clamp(scale(acc) + zero_point, lo, hi)` with the sum taken exactly.
pub fn requantize(acc: i32, multiplier: i32, shift: i32, zero_point: i32, lo: i8, hi: i8) -> i8 {
    let sum = i128::from(scale(acc, multiplier, shift)) + i128::from(zero_point);
    sum.clamp(i128::from(lo), i128::from(hi)) as i8
}

/// The two input planes' accumulator: `coarse * 2^8 + fine` exactly, then saturated to i32.
pub fn combine_planes(coarse: i32, fine: i32) -> i32 {
    saturate(i128::from(coarse) * 256 + i128::from(fine))
}

fn saturate(value: i128) -> i32 {
    value.clamp(i128::from(i32::MIN), i128::from(i32::MAX)) as i32
}

// --- The 16x8 scheme (int16 activations, int8 weights, int64 accumulators) ---------------------
//
// Written from the definitions in `/work/notes/int16-design.md` section 3.8 with i128 arithmetic
// and Euclidean divisions (residues by `rem_euclid`, quotients by `div_euclid`, the slope form of
// the table lookup), sharing no code or formulation with `quant::int16` and `kernels::lut16`.

/// The int64 accumulator of one row: `bias + sum over chunks c of sext32(sum_{i in c} w_i x_i mod
/// 2^32)`, chunks of `chunk` consecutive columns from column 0 (`chunk = 0` is taken as one chunk
/// for the whole row). Exact `bias + w . x` whenever every chunk's sum fits in i32.
pub fn accumulate_chunked<T: Copy + Into<i128>>(
    bias: i64,
    row: &[i8],
    input: &[T],
    chunk: usize,
) -> i128 {
    let len = row.len().min(input.len());
    let chunk = if chunk == 0 { len.max(1) } else { chunk };
    let mut total = i128::from(bias);
    let mut start = 0;
    while start < len {
        let end = start.saturating_add(chunk).min(len);
        let mut sum = 0_i128;
        for i in start..end {
            let (Some(w), Some(x)) = (row.get(i), input.get(i)) else {
                break;
            };
            sum += i128::from(*w) * (*x).into();
        }
        total += signed_residue(sum);
        start = end;
    }
    total
}

/// `v mod 2^32` as a signed 32-bit value, in i128.
fn signed_residue(v: i128) -> i128 {
    let r = v.rem_euclid(1_i128 << 32);
    if r >= 1_i128 << 31 {
        r - (1_i128 << 32)
    } else {
        r
    }
}

/// CMSIS-NN's `REDUCE_MULTIPLIER`: `0x7FFF` for `m >= 0x7FFF0000`, else `floor((m + 2^15) /
/// 2^16)`; negative results (negative `m`) are taken as 0.
pub fn reduce_multiplier16(m: i32) -> i32 {
    let m = i128::from(m);
    let reduced = if m >= 0x7FFF_0000 {
        0x7FFF
    } else {
        (m + (1 << 15)).div_euclid(1 << 16)
    };
    reduced.clamp(0, 0x7FFF) as i32
}

/// `clamp(floor((acc * m15 + 2^(T - 1)) / 2^T), lo, hi)` with `T = 15 - shift` and `m15 =
/// reduce_multiplier16(multiplier)`, exactly (for `shift` in `-31..=14`; `lo > hi` gives `hi`).
pub fn requantize16(acc: i128, multiplier: i32, shift: i32, lo: i16, hi: i16) -> i16 {
    let t = (15 - i64::from(shift)).clamp(1, 100) as u32;
    let product = acc * i128::from(reduce_multiplier16(multiplier));
    let rounded = (product + (1_i128 << (t - 1))).div_euclid(1_i128 << t);
    rounded.max(i128::from(lo)).min(i128::from(hi)) as i16
}

/// The interpolated int16 table at code `x`, slope form: with `q = floor(x / 128) + 256` and
/// `f = x mod 128`, `floor((128 t[q] + (t[q+1] - t[q]) f + 64) / 128)` (TFLite's lookup).
/// Returns `None` if `table` is shorter than `q + 2` entries.
pub fn lookup16(table: &[i16], x: i16) -> Option<i16> {
    let x = i128::from(x);
    let q = usize::try_from(x.div_euclid(128) + 256).ok()?;
    let f = x.rem_euclid(128);
    let left = i128::from(*table.get(q)?);
    let right = i128::from(*table.get(q + 1)?);
    let y = (128 * left + (right - left) * f + 64).div_euclid(128);
    i16::try_from(y).ok()
}

/// The int64 accumulator's f32 value by the split of `quant::dequantize_wide`, with the parts
/// from Euclidean division: `hi = floor((acc + 2^23) / 2^24)`, `lo = (acc + 2^23) mod 2^24 -
/// 2^23`, then `hi * (scale * 2^24) + lo * scale` in f32 (for `|acc| < 2^48`).
pub fn dequantize_wide(acc: i64, scale: f32) -> f32 {
    let shifted = i128::from(acc) + (1 << 23);
    let hi = shifted.div_euclid(1 << 24) as f32;
    let lo = (shifted.rem_euclid(1 << 24) - (1 << 23)) as f32;
    let high = hi * (scale * 16_777_216.0);
    let low = lo * scale;
    high + low
}
