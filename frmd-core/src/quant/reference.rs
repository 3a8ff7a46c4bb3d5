//! Wide-integer model (tests and the `reference` feature) of requantization, written directly from the formulas in
//! `quant::fixed_point` with i128 arithmetic and floor divisions (no masks, no nudges), so it
//! shares no code path with the implementation.

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
