//! The int8 activation table (`kernels::lut`) applied 64 codes per step with AVX-512 VBMI: the
//! 256-byte table sits in four 512-bit registers; `vpermi2b` looks every code's low seven bits up
//! in entries 0..128 and in entries 128..256, and the code's sign picks one of the two (table
//! entry `x + 128` for code `x`: negative codes read the first half). CPUs without VBMI keep
//! `lut::apply_in_place_by_words`.
#![allow(unsafe_code)]

use super::Avx2;
use crate::kernels::lut::{apply_in_place, apply_in_place_by_words, LutTable};
use core::arch::x86_64::{
    __m512i, _mm512_loadu_si512, _mm512_mask_blend_epi8, _mm512_movepi8_mask,
    _mm512_permutex2var_epi8, _mm512_storeu_si512,
};

/// Codes per step.
const STEP: usize = 64;

/// Loads 64 codes.
#[inline]
#[target_feature(enable = "avx512f")]
fn load(codes: &[i8; STEP]) -> __m512i {
    // SAFETY: the pointer comes from a `&[i8; 64]`: 64 initialized, readable bytes; `loadu` has
    // no alignment requirement.
    unsafe { _mm512_loadu_si512(codes.as_ptr().cast::<__m512i>()) }
}

#[target_feature(enable = "avx512f,avx512bw,avx512vbmi")]
fn apply_vbmi(table: &LutTable, data: &mut [i8]) {
    let (quarters, _) = table.as_chunks::<STEP>();
    let [negative_low, negative_high, positive_low, positive_high] = match quarters {
        [a, b, c, d] => [load(a), load(b), load(c), load(d)],
        _ => return apply_in_place(table, data),
    };
    let (steps, rest) = data.as_chunks_mut::<STEP>();
    for codes in steps {
        let x = load(codes);
        let negative = _mm512_permutex2var_epi8(negative_low, x, negative_high);
        let positive = _mm512_permutex2var_epi8(positive_low, x, positive_high);
        let mapped = _mm512_mask_blend_epi8(_mm512_movepi8_mask(x), positive, negative);
        // SAFETY: the pointer comes from a `&mut [i8; 64]`: 64 writable bytes; no alignment
        // needed.
        unsafe { _mm512_storeu_si512(codes.as_mut_ptr().cast::<__m512i>(), mapped) };
    }
    apply_in_place_by_words(table, rest);
}

impl Avx2 {
    /// Replaces every code of `data` by its entry in `table` (`lut::apply_in_place`'s result):
    /// 64 codes per step with AVX-512 VBMI, eight per word without.
    pub(crate) fn apply_table(self, table: &LutTable, data: &mut [i8]) {
        if self.vbmi() {
            // SAFETY: the token's `vbmi` flag is set only after `avx512_active()` and
            // `detect_vbmi` found AVX-512 F/BW (with the ZMM state) and VBMI.
            unsafe { apply_vbmi(table, data) }
        } else {
            apply_in_place_by_words(table, data);
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::kernels::lut::{apply_in_place, LutTable};
    use crate::kernels::x86::{test_tokens, Avx2};

    #[test]
    fn every_code_and_length_maps_as_the_portable_table() {
        let table: LutTable = core::array::from_fn(|i| (i as i8).wrapping_mul(37).wrapping_add(5));
        let codes: [i8; 300] = core::array::from_fn(|i| (i as u8).wrapping_mul(151) as i8);
        let mut tokens = test_tokens();
        tokens.extend(Avx2::get());
        for token in tokens {
            for len in 0..codes.len() {
                let (mut got, mut want) = (codes, codes);
                token.apply_table(&table, &mut got[..len]);
                apply_in_place(&table, &mut want[..len]);
                assert_eq!(got, want, "{token:?} length {len}");
            }
        }
    }
}
