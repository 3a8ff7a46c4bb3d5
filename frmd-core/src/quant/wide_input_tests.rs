//! The branch-free rounding and the 16-bit input plane.

extern crate std;

use super::*;
use crate::rng::SplitMix64;

fn libm_round(value: f32) -> i32 {
    libm::roundf(value) as i32 // `as` saturates, NaN -> 0
}

#[test]
fn branch_free_rounding_equals_libm_roundf() {
    let specials = [
        0.0_f32,
        -0.0,
        0.5,
        -0.5,
        0.49999997,
        -0.49999997,
        1.5,
        -2.5,
        8_388_607.5,
        -8_388_607.5,
        8_388_608.0,
        2_147_483_520.0,
        2_147_483_648.0,
        -2_147_483_648.0,
        -2_147_483_904.0,
        f32::MAX,
        f32::MIN,
        f32::MIN_POSITIVE,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];
    for value in specials {
        assert_eq!(round_to_i32(value), libm_round(value), "{value:e}");
    }
    // Every half-integer below 2^23 in magnitude and its two neighbours.
    for k in -(1_i32 << 22)..(1 << 22) {
        let half = k as f32 + 0.5;
        for value in [half, half.next_up(), half.next_down(), -half] {
            assert_eq!(round_to_i32(value), libm_round(value), "{value:e}");
        }
    }
    // A stride through all bit patterns.
    let mut bits = 0_u32;
    while let Some(next) = bits.checked_add(4099) {
        let value = f32::from_bits(bits);
        assert_eq!(round_to_i32(value), libm_round(value), "{bits:#x}");
        bits = next;
    }
}

#[test]
fn wide_codes_round_on_the_fine_grid_and_saturate() {
    let params = QuantParams::new(0.02, -3).unwrap();
    assert_eq!(wide_zero_point(params), -640);
    assert_eq!(wide_scale(params), 0.02 / 256.0);
    assert_eq!(quantize_i16(0.0, params), -640);
    assert_eq!(quantize_i16(f32::NAN, params), -640);
    assert_eq!(quantize_i16(1e9, params), i16::MAX);
    assert_eq!(quantize_i16(-1e9, params), i16::MIN);
    assert_eq!(quantize_i16(f32::INFINITY, params), i16::MAX);
    let mut rng = SplitMix64::new(0x16);
    for _ in 0..100_000 {
        let u = (rng.next_u64() >> 40) as f32 / (1 << 24) as f32;
        let value = (u - 0.5) * 6.0;
        let code = quantize_i16(value, params);
        let want = (libm_round(value / (0.02 / 256.0)) - 640).clamp(-32768, 32767);
        assert_eq!(i32::from(code), want, "{value}");
        if want > -32768 && want < 32767 {
            // Inside the range the code represents the value to half a fine step (plus f32 rounding).
            let back = dequantize_i16(code, params);
            assert!(
                (back - value).abs() <= 0.51 * 0.02 / 256.0,
                "{value} -> {back}"
            );
            // The two planes describe the same fine grid over the same range, within one fine
            // step (their fine code is rounded from an f32 residual).
            let (coarse, fine) = quantize_two_plane(value, params);
            let planes = i32::from(coarse) * 256 + i32::from(fine) + 128;
            assert!(
                (planes - i32::from(code)).abs() <= 1,
                "{value}: {planes} vs {code}"
            );
        }
    }
}
