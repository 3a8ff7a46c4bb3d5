//! The AVX2 int64 kernels against the portable definitions: requantization and table lanes on
//! edge and random values (valid parameters and garbage alike), and the chunked accumulation.

extern crate std;

use super::*;
use crate::kernels::lut16::lookup;
use crate::quant::{reference, SHIFT16_MAX, SHIFT16_MIN};
use crate::rng::SplitMix64;
use std::vec::Vec;

const EDGES: [i64; 16] = [
    i64::MIN,
    i64::MIN + 1,
    -(1 << 47),
    -(1 << 46) - 1,
    -(1 << 31) - 1,
    -(1 << 31),
    -1,
    0,
    1,
    (1 << 31) - 1,
    1 << 31,
    (1 << 46) + 1,
    (1 << 47) - 1,
    1 << 47,
    i64::MAX - 1,
    i64::MAX,
];

fn scalar(
    acc: &[i64; 8],
    requant: RequantBlock16<'_>,
    table: Option<&Lut16Table>,
) -> [i16; BLOCK_ROWS] {
    core::array::from_fn(|i| {
        let (lo, hi) = requant.bounds;
        let y = requantize_s64(acc[i], requant.multipliers[i], requant.shifts[i], lo, hi);
        table.map_or(y, |t| lookup(t, y))
    })
}

#[test]
fn requantization_lanes_match_scalar() {
    let Some(avx2) = Avx2::get() else {
        std::eprintln!("no AVX2 on this CPU: the int64 AVX2 kernels are not exercised");
        return;
    };
    let mut rng = SplitMix64::new(0x5EED_0016);
    let span = (SHIFT16_MAX - SHIFT16_MIN + 1) as u64;
    let mut unclamped = 0_usize;
    let tables: Vec<Lut16Table> = (0..4)
        .map(|_| core::array::from_fn(|_| rng.next_u64() as i16))
        .collect();
    for case in 0..200_000 {
        let valid = case % 4 != 0;
        let mut pick_acc = || {
            let bits = rng.next_u64();
            if bits.is_multiple_of(8) {
                EDGES[((bits >> 8) % EDGES.len() as u64) as usize]
            } else if valid {
                // The exact domain with random magnitudes.
                ((bits >> 16) as i64 - (1 << 47)) >> ((bits >> 8) % 48)
            } else {
                bits as i64
            }
        };
        let acc: [i64; 8] = core::array::from_fn(|_| pick_acc());
        let multipliers: [i32; 8] = core::array::from_fn(|_| {
            let bits = rng.next_u64();
            if valid {
                (1 << 30) + (bits % (1 << 30)) as i32
            } else {
                bits as i32
            }
        });
        let shifts: [i32; 8] = core::array::from_fn(|_| {
            let bits = rng.next_u64();
            if valid {
                SHIFT16_MIN + (bits % span) as i32
            } else {
                bits as i32
            }
        });
        let bounds = match case % 3 {
            0 => (i16::MIN, i16::MAX),
            1 => (0, i16::MAX),
            _ => (rng.next_u64() as i16, rng.next_u64() as i16),
        };
        let requant = RequantBlock16 {
            multipliers: &multipliers,
            shifts: &shifts,
            bounds,
        };
        let table = (case % 2 == 0).then(|| &tables[case % tables.len()]);
        let got = avx2.requantize_wide(&acc, requant, table);
        let want = scalar(&acc, requant, table);
        assert_eq!(
            got, want,
            "acc {acc:?} m {multipliers:?} s {shifts:?} {bounds:?}"
        );
        if valid && table.is_none() {
            for (i, y) in want.iter().enumerate() {
                if bounds.0 <= bounds.1 && (-(1 << 47)..=1 << 47).contains(&acc[i]) {
                    let model = reference::requantize16(
                        i128::from(acc[i]),
                        multipliers[i],
                        shifts[i],
                        bounds.0,
                        bounds.1,
                    );
                    assert_eq!(*y, model);
                }
                unclamped += usize::from(*y != bounds.0 && *y != bounds.1);
            }
        }
    }
    assert!(unclamped > 50_000, "{unclamped} unclamped outputs");
}

#[test]
fn wide_accumulation_matches_the_model() {
    for avx2 in crate::kernels::x86::test_tokens() {
        wide_accumulation_matches(avx2);
    }
}

fn wide_accumulation_matches(avx2: Avx2) {
    let mut rng = SplitMix64::new(0x0ACC_0016);
    for case in 0..300 {
        let width = match case % 6 {
            0 => 512 * (1 + (rng.next_u64() % 3) as usize),
            1 => 511 + (rng.next_u64() % 3) as usize,
            _ => 1 + (rng.next_u64() % 1600) as usize,
        };
        let weights: Vec<i8> = (0..BLOCK_ROWS * width)
            .map(|_| match case % 3 {
                0 => [-128_i8, 127][(rng.next_u64() % 2) as usize],
                _ => rng.next_u64() as i8,
            })
            .collect();
        let input: Vec<i16> = (0..width)
            .map(|_| match case % 3 {
                0 => [i16::MIN, i16::MAX][(rng.next_u64() % 2) as usize],
                _ => rng.next_u64() as i16,
            })
            .collect();
        let bytes: Vec<i8> = input.iter().map(|x| *x as i8).collect();
        let bias: [i64; 8] = core::array::from_fn(|_| (rng.next_u64() as i64) >> 17);
        let want = |values: &dyn Fn(usize) -> i128| -> [i64; 8] {
            core::array::from_fn(|r| {
                let row = &weights[r * width..(r + 1) * width];
                let x: Vec<i128> = (0..width).map(values).collect();
                reference::accumulate_chunked(bias[r], row, &x, crate::quant::CHUNK16) as i64
            })
        };
        let got = avx2.accumulate_rows_wide(&weights, LayerInput::Int16(&input), &bias);
        assert_eq!(
            got,
            want(&|i| i128::from(input[i])),
            "{avx2:?} width {width}"
        );
        let got = avx2.accumulate_rows_wide(&weights, LayerInput::Int8(&bytes), &bias);
        assert_eq!(
            got,
            want(&|i| i128::from(bytes[i])),
            "width {width} (int8 input)"
        );
    }
}
