//! Bit-accuracy check (d) of docs/design.md section 6: frmd-core's int8 kernels against an
//! independent wide-integer model of the same formulas (`frmd_core::quant::reference`, i128
//! arithmetic with floor divisions; i64 dot products in the per-backbone checks), on random and
//! edge inputs. Here: the outcome type and the requantization check every backbone shares; the
//! exported networks' checks are `mlp::reference` and `transformer::reference`.
use frmd_core::quant::reference::{self, EDGE_ZERO_POINTS};
use frmd_core::quant::reference::{edge_accumulators, EDGE_CLAMPS, EDGE_MULTIPLIERS};
use frmd_core::quant::{
    multiply_by_quantized_multiplier, requantize_to_i8, Q31_MANTISSA_MIN, SHIFT_MAX, SHIFT_MIN,
};
use frmd_core::rng::Rng;

/// Outcome of one check: how many cases ran and how many differed (the first is described).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KernelCheck {
    /// What was checked.
    pub name: String,
    /// Cases run.
    pub cases: u64,
    /// Cases that differed.
    pub mismatches: u64,
    /// The first differing case.
    pub first_mismatch: Option<String>,
}

impl KernelCheck {
    pub(crate) fn new(name: &str) -> Self {
        KernelCheck {
            name: name.into(),
            cases: 0,
            mismatches: 0,
            first_mismatch: None,
        }
    }

    pub(crate) fn record(&mut self, equal: bool, describe: impl FnOnce() -> String) {
        self.cases += 1;
        if !equal {
            self.mismatches += 1;
            if self.first_mismatch.is_none() {
                self.first_mismatch = Some(describe());
            }
        }
    }

    /// Some cases ran and none differed.
    pub fn passed(&self) -> bool {
        self.mismatches == 0 && self.cases > 0
    }
}

/// Requantization on all edge accumulators (INT32 ends, powers of two and neighbours) x edge
/// multipliers x every shift x zero points at the range ends x clamps, then `random` random cases,
/// and exact ties of the final rounding division.
pub fn check_requantization(random: u64, seed: u64) -> KernelCheck {
    let mut check = KernelCheck::new("requantization (edges, ties, random) vs i128 model");
    for &acc in &edge_accumulators() {
        for &m in &EDGE_MULTIPLIERS {
            for shift in SHIFT_MIN..=SHIFT_MAX {
                let got = multiply_by_quantized_multiplier(acc, m, shift);
                let want = reference::scale(acc, m, shift);
                check.record(got == want, || {
                    format!("scale acc={acc} m={m} shift={shift}: {got} vs {want}")
                });
                for &zp in &EDGE_ZERO_POINTS {
                    for &(lo, hi) in &EDGE_CLAMPS {
                        let got = requantize_to_i8(acc, m, shift, zp, lo, hi);
                        let want = reference::requantize(acc, m, shift, zp, lo, hi);
                        check.record(got == want, || format!("acc={acc} m={m} shift={shift} zp={zp} clamp={lo}..={hi}: {got} vs {want}"));
                    }
                }
            }
        }
    }
    // Ties: acc * m / 2^31 = h exactly (m = 2^30, acc even), h an odd multiple of 2^(r-1).
    for r in 1..=20_i32 {
        for odd in [-7_i64, -3, -1, 1, 3, 7] {
            let h = odd << (r - 1);
            let acc = (2 * h) as i32;
            let got = multiply_by_quantized_multiplier(acc, Q31_MANTISSA_MIN, -r);
            let want = reference::scale(acc, Q31_MANTISSA_MIN, -r);
            check.record(got == want, || {
                format!("tie acc={acc} shift={}: {got} vs {want}", -r)
            });
        }
    }
    let mut rng = Rng::new(seed);
    for _ in 0..random {
        let acc = rng.next_u32() as i32;
        let m = Q31_MANTISSA_MIN + (rng.next_u32() % (1 << 30)) as i32;
        let shift = SHIFT_MIN + (rng.next_u32() % (SHIFT_MAX - SHIFT_MIN + 1) as u32) as i32;
        let zp = (rng.next_u32() % 256) as i32 - 128;
        let got = requantize_to_i8(acc, m, shift, zp, i8::MIN, i8::MAX);
        let want = reference::requantize(acc, m, shift, zp, i8::MIN, i8::MAX);
        check.record(got == want, || {
            format!("random acc={acc} m={m} shift={shift} zp={zp}: {got} vs {want}")
        });
    }
    check
}
