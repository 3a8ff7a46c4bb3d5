//! The table sampler: its table against frmd-core's own f64 quantile, the interpolation error,
//! the branch-free pieces, and the statistics of the stream (moments, tails, CDF).

extern crate std;

use super::super::Rng;
use super::*;
use std::vec::Vec;

/// `Q(p)`: the `|z|` with `P(|Z| > |z|) = erfc(|z| / sqrt 2) = p`, by bisection in f64.
fn half_normal_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if libm::erfc(mid / core::f64::consts::SQRT_2) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// `P(|Z| > z)`.
fn tail(z: f64) -> f64 {
    libm::erfc(z / core::f64::consts::SQRT_2)
}

#[test]
fn table_holds_the_quantiles() {
    for k in 0..OCTAVES {
        for j in 0..=SEGMENTS {
            let p = libm::exp2(-(k as f64 + 1.0)) * (1.0 + j as f64 / SEGMENTS as f64);
            let want = libm::round(half_normal_quantile(p) * 1_048_576.0) as i64;
            let got = i64::from(TABLE[k * (SEGMENTS + 1) + j]);
            assert!(
                (got - want).abs() <= 1,
                "octave {k} segment {j}: {got} vs {want}"
            );
        }
        // Octaves meet: the end of octave k + 1 is the start of octave k.
        if k + 1 < OCTAVES {
            assert_eq!(
                TABLE[(k + 1) * (SEGMENTS + 1) + SEGMENTS],
                TABLE[k * (SEGMENTS + 1)]
            );
        }
    }
    // The interpolation product fits in i32.
    let segments = TABLE
        .chunks_exact(SEGMENTS + 1)
        .flat_map(|octave| octave.windows(2));
    let widest = segments.map(|w| (w[1] - w[0]).abs()).max().unwrap();
    assert!(i64::from(widest) << FRACTION_BITS < 1 << 31, "{widest}");
}

#[test]
fn samples_follow_the_quantile_function() {
    // Every octave at many positions: the sample is within 2.5e-4 of Q(p) (interpolation error
    // plus the grid), with the sign from the top bit.
    let mut rng = Rng::new(11);
    let mut worst = 0.0_f64;
    for octave in 0..31_u32 {
        for _ in 0..2000 {
            let low = rng.next_u32() >> (octave + 1);
            let m = (1_u32 << (30 - octave)) | (low & ((1 << (30 - octave)) - 1));
            let p = f64::from(m) / 2_147_483_648.0;
            let want = half_normal_quantile(p.max(libm::exp2(-26.0)));
            let z = f64::from(normal_q20(m)) / 1_048_576.0;
            assert_eq!(normal_q20(m | 1 << 31), -normal_q20(m));
            worst = worst.max((z - want).abs());
        }
    }
    assert!(worst < 2.5e-4, "worst error {worst}");
    // The ends: p just below 1 gives |z| of one unit, p = 0 the last table value.
    assert_eq!(normal_q20(0x7FFF_FFFF), 1);
    assert_eq!(normal_q20(u32::MAX), -1);
    assert_eq!(normal_q20(0), TABLE[(OCTAVES - 1) * (SEGMENTS + 1)]);
}

#[test]
fn branch_free_leading_zeros_equal_the_instruction() {
    let mut rng = Rng::new(3);
    let specials = [0_u32, 1, 2, 3, 0x7FFF_FFFF, 0x8000_0000, u32::MAX];
    let shifted = (0..32).flat_map(|s| [1_u32 << s, (1_u32 << s) - 1, (1_u32 << s) | 1]);
    let random = (0..10_000).map(|i| rng.next_u32() >> (i % 32));
    for x in specials.into_iter().chain(shifted).chain(random) {
        assert_eq!(leading_zeros_branch_free(x), x.leading_zeros(), "{x:#x}");
    }
}

#[test]
fn gaussian_stream_is_pinned() {
    // Pins the stream: each sample is the table value of one raw draw, times 2^-20.
    let mut raw = Rng::new(2024);
    let mut rng = Rng::new(2024);
    let mut pair = [0.0_f32; 2];
    rng.fill_gaussian(&mut pair);
    for z in pair {
        let want = normal_q20(raw.next_u32()) as f32 / 1_048_576.0;
        assert_eq!(z.to_bits(), want.to_bits());
    }
    assert_eq!(rng.next_u32(), raw.next_u32());
    // Two fixed draws by hand: the sign bit, then octave 0 segment 0 (p = 1/2, Q = 0.6745).
    assert_eq!(normal_q20(0x4000_0000), TABLE[0]);
    assert_eq!(normal_q20(0xC000_0000), -TABLE[0]);
    assert!((f64::from(TABLE[0]) / 1_048_576.0 - 0.674_49).abs() < 1e-5);
}

#[test]
fn gaussian_moments() {
    let mut rng = Rng::new(7);
    let n = 100_000;
    let (mut sum, mut sum2, mut sum3, mut sum4) = (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    let mut max_abs = 0.0_f32;
    for _ in 0..n {
        let z = rng.gaussian();
        assert!(z.is_finite());
        max_abs = max_abs.max(z.abs());
        let z = f64::from(z);
        sum += z;
        sum2 += z * z;
        sum3 += z * z * z;
        sum4 += z * z * z * z;
    }
    let n = f64::from(n);
    let mean = sum / n;
    let var = sum2 / n - mean * mean;
    // Standard errors: mean 1/sqrt(n) = 0.0032, variance sqrt(2/n) = 0.0045.
    assert!(mean.abs() < 0.015, "mean {mean}");
    assert!((var - 1.0).abs() < 0.02, "variance {var}");
    assert!((sum3 / n).abs() < 0.05, "third moment {}", sum3 / n);
    assert!((sum4 / n - 3.0).abs() < 0.1, "fourth moment {}", sum4 / n);
    assert!(max_abs > 3.5 && max_abs <= 5.8, "max |z| {max_abs}");
}

#[test]
fn gaussian_tails_and_distribution() {
    // 4M draws: the fraction beyond 2, 3, 4 and 4.5 standard deviations within 5 binomial
    // standard errors of P(|Z| > t), and the empirical CDF within 0.002 of Phi at 13 points
    // (Kolmogorov-Smirnov: the 99.9 % critical value for n = 4M is 0.001).
    let mut rng = Rng::new(0x7A11);
    let n = 4_000_000_u32;
    let thresholds = [2.0_f64, 3.0, 4.0, 4.5];
    let points: Vec<f64> = (-6..=6).map(|i| f64::from(i) * 0.5).collect();
    let mut beyond = [0_u32; 4];
    let mut below = std::vec![0_u32; points.len()];
    for _ in 0..n {
        let z = f64::from(rng.gaussian());
        for (count, t) in beyond.iter_mut().zip(thresholds) {
            *count += u32::from(z.abs() > t);
        }
        for (count, x) in below.iter_mut().zip(&points) {
            *count += u32::from(z <= *x);
        }
    }
    let n = f64::from(n);
    for (count, t) in beyond.iter().zip(thresholds) {
        let p = tail(t);
        let se = (p * (1.0 - p) / n).sqrt();
        let got = f64::from(*count) / n;
        assert!((got - p).abs() < 5.0 * se, "P(|z| > {t}): {got:e} vs {p:e}");
    }
    for (count, x) in below.iter().zip(&points) {
        let cdf = if *x < 0.0 {
            0.5 * tail(-x)
        } else {
            1.0 - 0.5 * tail(*x)
        };
        let got = f64::from(*count) / n;
        assert!((got - cdf).abs() < 0.002, "CDF({x}): {got} vs {cdf}");
    }
}
