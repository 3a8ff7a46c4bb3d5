//! Two-plane input quantization: the plane split and the combined accumulator against the
//! wide-integer model.

extern crate std;

use super::reference;
use super::*;
use crate::rng::SplitMix64;

#[test]
fn combined_accumulator_matches_wide_model_on_edges() {
    let mut values = std::vec![i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
    for e in 0..31 {
        let p = 1_i32 << e;
        values.extend([p, p - 1, p + 1, -p, -p - 1]);
    }
    let mut saturated = 0;
    for &coarse in &values {
        for &fine in &values {
            let got = combine_plane_accumulators(coarse, fine);
            assert_eq!(
                got,
                reference::combine_planes(coarse, fine),
                "{coarse} {fine}"
            );
            saturated += usize::from(got == i32::MAX || got == i32::MIN);
        }
    }
    // Both saturation directions are exercised, and a small case is exact.
    assert!(saturated > 100);
    assert_eq!(combine_plane_accumulators(-3, 5), -3 * 256 + 5);
    assert_eq!(combine_plane_accumulators(1 << 23, -1), i32::MAX);
    assert_eq!(combine_plane_accumulators(-(1 << 23), 0), i32::MIN);
    let mut rng = SplitMix64::new(0x2b1a);
    for _ in 0..100_000 {
        let (coarse, fine) = (
            rng.next_u64() as i32 >> (rng.next_u64() % 24),
            rng.next_u64() as i32 >> 8,
        );
        assert_eq!(
            combine_plane_accumulators(coarse, fine),
            reference::combine_planes(coarse, fine)
        );
    }
}

#[test]
fn two_plane_codes_represent_the_value_to_a_fine_step() {
    let params = QuantParams::from_range(-1.3, 2.1).unwrap();
    let fine_step = params.scale / 256.0;
    let (lo, hi) = (params.dequantize(i8::MIN), params.dequantize(i8::MAX));
    let mut rng = SplitMix64::new(7);
    for _ in 0..20_000 {
        let u = (rng.next_u64() >> 40) as f32 / (1_u64 << 24) as f32;
        let value = lo + u * (hi - lo);
        let (coarse, fine) = quantize_two_plane(value, params);
        assert_eq!(
            coarse,
            params.quantize(value),
            "the coarse plane is the int8 code"
        );
        let represented = params.dequantize(coarse) + f32::from(fine) * fine_step;
        // Half a fine step, or one where the residual sits at +half a coarse step (128 fine
        // steps saturate to 127).
        assert!(
            (represented - value).abs() <= fine_step + 1e-6,
            "{value}: {represented}"
        );
    }
    // A residual of exactly +-1.5 fine steps rounds half away from zero.
    let (coarse, fine) = quantize_two_plane(params.dequantize(10) + 1.5 * fine_step, params);
    assert_eq!((coarse, fine), (10, 2));
    let (coarse, fine) = quantize_two_plane(params.dequantize(10) - 1.5 * fine_step, params);
    assert_eq!((coarse, fine), (10, -2));
    // Beyond the range both planes saturate; NaN maps to the zero point and a zero residual.
    assert_eq!(quantize_two_plane(1e6, params), (127, 127));
    assert_eq!(quantize_two_plane(-1e6, params), (-128, -128));
    let (coarse, _) = quantize_two_plane(f32::NAN, params);
    assert_eq!(coarse as i32, params.zero_point);
}
