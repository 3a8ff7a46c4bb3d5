//! AVX2 builds of the int8 kernels for x86-64, chosen at run time; the portable kernels
//! (`kernels::rows::for_each_block`, SSE2 through LLVM, and `quant::requantize_to_i8`) are the
//! fallback and the definition: the tests compare both on random and extreme inputs.
//!
//! - `matvec`: eight rows of a fully connected layer at once (`vpmaddwd`, or a `vpdpbusd` /
//!   `vpdpwssd` front from `vnni` on CPUs with AVX-VNNI or AVX-512 VNNI);
//! - `layer`: the loops over a whole layer's blocks of eight rows, one per kernel level, with
//!   the bias added and, for hidden layers, requantized (and the int16 table applied) in
//!   registers;
//! - `requant`: requantization of eight accumulators at once;
//! - `packed`: whole layers of weights packed for `vpdpbusd` (`kernels::packed`), sixteen rows
//!   per instruction, int16 inputs split into bytes;
//! - `table`: the int8 activation table, 64 codes per step with AVX-512 VBMI;
//! - `vnni`: the fronts of the row sums with `vpdpbusd`/`vpdpwssd`, VEX-encoded on 256 bits
//!   (AVX-VNNI) or EVEX-encoded on 512 bits (AVX-512 F/BW/VNNI, checked with [`avx512_active`]);
//! - `wide`: the int16-activation layers (int64 accumulation from 512-column int32 chunk sums,
//!   requantization to int16 and the interpolated table in registers);
//! - `decode`: the hosts' ProDMP decode, eight DoFs per pass;
//! - `dequant`: dequantization of int64 accumulators to f32, eight at a time.
//!
//! Detection is `no_std`: `CPUID` leaf 1 (AVX and OSXSAVE bits), `XGETBV` (the OS saves the SSE
//! and AVX register state: XCR0 bits 1 and 2) and `CPUID` leaf 7 (AVX2 bit), cached in an
//! atomic; AVX-VNNI is `CPUID` leaf 7 subleaf 1. [`set_avx2_enabled`] and
//! [`set_avx_vnni_enabled`] turn the paths off (or back on, if the CPU has them) for A/B
//! measurements.
//!
//! Safety audit: `unsafe` is allowed in this module and its submodules only (and in
//! `kernels::dsp_asm`). There are four kinds of `unsafe` expression:
//! - `_xgetbv(0)` here: requires the `XGETBV` instruction, which exists when `CPUID.1:ECX.OSXSAVE`
//!   (bit 27) is set; it is called only after checking that bit.
//! - calls of `#[target_feature(enable = "avx2")]` functions from the methods of the `Avx2`
//!   token: sound when the CPU supports AVX2 and the OS enabled the AVX state. A token is made
//!   only by `Avx2::get` after [`avx2_active`] returned true, and that state only becomes
//!   "active" through `detect_avx2`. The `avx2,avxvnni` functions are called only when the
//!   token's `vnni` flag is set, which [`avx_vnni_active`] sets only after `detect_avx_vnni`;
//!   the `avx512f,avx512bw,avx512vnni` functions only when its `avx512` flag is set, which
//!   [`avx512_active`] sets only after `detect_avx512` (CPUID bits and the ZMM state in XCR0),
//!   and the `avx512vbmi` one only when its `vbmi` flag is set, which needs that flag and
//!   `detect_vbmi`.
//!   (Disabling a path later leaves existing tokens valid: the CPU still has the instructions.)
//! - unaligned loads and stores (`_mm_loadu_si128`, `_mm256_loadu_si256`, `_mm256_storeu_si256`,
//!   `_mm_storeu_si128`) through pointers made from references to fixed-size arrays of exactly
//!   the accessed size (`&[i8; 16]`, `&[i8; 32]`, `&[i8; 64]` (`_mm512_loadu_si512`),
//!   `&[u8; 32]`, `&[u8; 64]`, `&[i16; 32]`, `&[i16; 16]`, `&[i16; 8]`, `&[i32; 8]`,
//!   `&[i64; 4]`, `&[f32; 8]`, `&mut [i8; 64]` (`_mm512_storeu_si512`), `&mut [i32; 4]`, `&mut [i32; 8]`,
//!   `&mut [i16; 8]`, `&mut [i64; 4]`, `&mut [f32; 8]`): in bounds, initialized, no alignment
//!   needed.
//! - `_mm256_i32gather_epi32` in `wide::interpolate`: eight 4-byte reads from a `&[i16; 513]`
//!   table at byte offsets `2 i` with every index `i` masked to `0..=511`, so each read
//!   (`t[i]`, `t[i + 1]`) ends at byte 1026 at most, inside the table.
//!
//! No other memory is touched: slices are walked with `as_chunks` iterators.
#![allow(unsafe_code)]

mod decode;
mod dequant;
mod layer;
mod matvec;
mod packed;
mod requant;
mod table;
mod vnni;
mod wide;

/// Output channels (weight rows) per call of the row kernels, and lanes of a requantized block.
pub(crate) const BLOCK_ROWS: usize = 8;

pub(crate) use decode::DECODE_LANES;

/// Each of the eight rows from column `start` on (empty if `start` is past its end).
#[inline(always)]
pub(crate) fn rows_from(rows: [&[i8]; BLOCK_ROWS], start: usize) -> [&[i8]; BLOCK_ROWS] {
    rows.map(|row| row.get(start..).unwrap_or(&[]))
}

use super::{FcRequant, FullyConnected};

/// One output channel of a layer: its output, weight row, bias, multiplier and shift.
pub(crate) type RowOf<'a, O, B> = (&'a mut O, &'a [i8], &'a B, i32, i32);

/// Calls `row` for every output channel of `layer` after its last whole block of
/// [`BLOCK_ROWS`] (the channels the block kernels of `x86::layer` leave to the portable code).
/// Calls nothing when `in_features * BLOCK_ROWS` overflows (callers checked the lengths).
#[inline(always)]
pub(crate) fn for_each_tail_row<O, B>(
    layer: &FullyConnected<'_, B>,
    requant: &FcRequant<'_, O>,
    output: &mut [O],
    mut row: impl FnMut(RowOf<'_, O, B>),
) {
    let width = layer.in_features;
    let Some(block_len) = width.checked_mul(BLOCK_ROWS) else {
        return;
    };
    let rows = layer.weights.chunks_exact(block_len).remainder();
    let tail = output
        .as_chunks_mut::<BLOCK_ROWS>()
        .1
        .iter_mut()
        .zip(rows.chunks_exact(width))
        .zip(layer.bias.as_chunks::<BLOCK_ROWS>().1)
        .zip(
            requant
                .multipliers
                .as_chunks::<BLOCK_ROWS>()
                .1
                .iter()
                .zip(requant.shifts.as_chunks::<BLOCK_ROWS>().1),
        );
    for (((out, weights), bias), (multiplier, shift)) in tail {
        row((out, weights, bias, *multiplier, *shift));
    }
}

use crate::kernels::switch::KernelSwitch;
#[cfg(test)]
use alloc::vec::Vec;
use core::arch::x86_64::{__cpuid, __cpuid_count, _xgetbv};

static AVX2: KernelSwitch = KernelSwitch::probed(detect_avx2);

/// Proof that the AVX2 kernels may run: `Avx2::get` hands one out only while [`avx2_active`]
/// is true. The kernels are methods of this token (`matvec`, `requant`). `vnni` records whether
/// the AVX-VNNI variant of the matrix-vector kernel may run too ([`avx_vnni_active`]), `avx512`
/// whether the AVX-512 VNNI one may ([`avx512_active`]), `packed` whether layers with packed
/// weights run them ([`packed_active`]; with AVX-512 VNNI where the CPU has it, the faster of
/// the two there: `x86::packed`). Where both VNNI levels may, the row-major layers run the 256-bit
/// AVX-VNNI level: it timed faster on both machines measured (an Intel Xeon with AMX and an AMD
/// EPYC Zen 4; MLP-256 int8 chunk 4.0 against 5.0 us on the EPYC, README's benchmark section), so
/// AVX-512 runs only on CPUs without AVX-VNNI (Ice Lake and Cascade Lake servers, Zen 4 if its
/// AVX-VNNI flag is hidden).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2 {
    vnni: bool,
    avx512: bool,
    packed: bool,
    vbmi: bool,
}

impl Avx2 {
    /// The token, if the CPU and OS support AVX2 and the path is enabled.
    #[inline]
    pub(crate) fn get() -> Option<Self> {
        avx2_active().then(|| Self {
            vnni: avx_vnni_active(),
            avx512: avx512_active(),
            packed: PACKED.active(),
            vbmi: avx512_active() && VBMI.active(),
        })
    }

    /// Whether the AVX-VNNI instructions (`vpdpbusd`, VEX-encoded) may be used.
    #[inline]
    pub(crate) fn vnni(self) -> bool {
        self.vnni
    }

    /// Whether the AVX-512 F/BW/VNNI instructions may be used.
    #[inline]
    pub(crate) fn avx512(self) -> bool {
        self.avx512
    }

    /// Whether AVX-512 VBMI may be used too (`vpermi2b`: `x86::table`).
    #[inline]
    pub(crate) fn vbmi(self) -> bool {
        self.vbmi
    }
}

/// (Tests) every kernel level this CPU runs: AVX2 alone, with AVX-VNNI, with AVX-512 VNNI.
#[cfg(test)]
pub(crate) fn test_tokens() -> Vec<Avx2> {
    extern crate std;
    let Some(detected) = Avx2::get() else {
        std::eprintln!("no AVX2 on this CPU: only the portable kernels are exercised");
        return Vec::new();
    };
    let plain = Avx2 {
        vnni: false,
        avx512: false,
        packed: true,
        vbmi: false,
    };
    let mut tokens = std::vec![plain];
    for (present, token, name) in [
        (
            detected.vnni,
            Avx2 {
                vnni: true,
                ..plain
            },
            "AVX-VNNI",
        ),
        (
            detected.avx512,
            Avx2 {
                avx512: true,
                vbmi: detected.vbmi,
                ..plain
            },
            "AVX-512 VNNI",
        ),
    ] {
        if present {
            tokens.push(token);
        } else {
            std::eprintln!("no {name} on this CPU: its kernels are not exercised");
        }
    }
    tokens
}

/// The packed-weight kernels' switch (`x86::packed`; only consulted with a VNNI level).
static PACKED: KernelSwitch = KernelSwitch::baseline();

/// Whether layers with packed weights (`kernels::packed`) run them: a VNNI level is active and
/// the packed kernels are not switched off.
pub fn packed_active() -> bool {
    PACKED.active() && (avx512_active() || avx_vnni_active())
}

/// Enables or disables the packed-weight kernels, process-wide (layers then run their
/// row-major weights with the active level; identical results, for A/B measurements); returns
/// whether they are active afterwards.
pub fn set_packed_enabled(enabled: bool) -> bool {
    PACKED.set(enabled);
    packed_active()
}

/// AVX-512's switch (only consulted while AVX2 is active).
static AVX512: KernelSwitch = KernelSwitch::probed(avx512_supported);

/// Whether the CPU and OS support AVX-512 F, BW and VNNI (with the ZMM register state saved).
pub fn avx512_supported() -> bool {
    detect_avx2() && detect_avx512()
}

/// Whether the int8 and int16 row kernels currently use their AVX-512 VNNI variant.
#[inline]
pub fn avx512_active() -> bool {
    avx2_active() && AVX512.active()
}

/// Enables (if supported) or disables the AVX-512 variant, process-wide; returns whether it is
/// active afterwards. All variants give identical results (for A/B measurements).
pub fn set_avx512_enabled(enabled: bool) -> bool {
    AVX512.set(enabled) && avx2_active()
}

/// `CPUID.(7,0)`: AVX512F (EBX bit 16), AVX512BW (EBX bit 30), AVX512_VNNI (ECX bit 11); `XGETBV`:
/// the OS saves the opmask and both ZMM state components (XCR0 bits 5, 6, 7) besides SSE/AVX.
fn detect_avx512() -> bool {
    const F: u32 = 1 << 16;
    const BW: u32 = 1 << 30;
    const VNNI: u32 = 1 << 11;
    const OSXSAVE: u32 = 1 << 27;
    const XCR0_ZMM: u64 = 0b1110_0110;
    if __cpuid(0).eax < 7 || __cpuid(1).ecx & OSXSAVE == 0 {
        return false;
    }
    // SAFETY: CPUID.1:ECX.OSXSAVE is set (checked above), so XGETBV is available and XCR0 readable.
    let xcr0 = unsafe { _xgetbv(0) };
    let leaf = __cpuid_count(7, 0);
    xcr0 & XCR0_ZMM == XCR0_ZMM && leaf.ebx & (F | BW) == F | BW && leaf.ecx & VNNI != 0
}

/// AVX-512 VBMI's probe (only consulted while AVX-512 is active).
static VBMI: KernelSwitch = KernelSwitch::probed(detect_vbmi);

/// `CPUID.(7,0):ECX.AVX512_VBMI` (bit 1); the ZMM state is `detect_avx512`'s check, which every
/// caller requires as well.
fn detect_vbmi() -> bool {
    const VBMI: u32 = 1 << 1;
    __cpuid(0).eax >= 7 && __cpuid_count(7, 0).ecx & VBMI != 0
}

/// AVX-VNNI's switch (only consulted while AVX2 is active).
static VNNI: KernelSwitch = KernelSwitch::probed(avx_vnni_supported);

/// Whether the CPU supports AVX-VNNI (VEX-encoded `vpdpbusd`; Intel Alder Lake and later, AMD
/// Zen 5; also reported by Zen 4) besides AVX2.
pub fn avx_vnni_supported() -> bool {
    detect_avx2() && detect_avx_vnni()
}

/// Whether the int8 matrix-vector kernel currently uses the AVX-VNNI variant.
#[inline]
pub fn avx_vnni_active() -> bool {
    avx2_active() && VNNI.active()
}

/// Enables (if supported) or disables the AVX-VNNI variant, process-wide; returns whether it is
/// active afterwards. All variants give identical results (for A/B measurements).
pub fn set_avx_vnni_enabled(enabled: bool) -> bool {
    VNNI.set(enabled) && avx2_active()
}

/// Whether the CPU and the OS support AVX2 (probed with `CPUID`/`XGETBV`).
pub fn avx2_supported() -> bool {
    AVX2.supported()
}

/// Whether the int8 kernels currently use the AVX2 build.
#[inline]
pub fn avx2_active() -> bool {
    AVX2.active()
}

/// Enables (if the CPU supports it) or disables the AVX2 build of the int8 kernels, process-wide.
/// Returns whether AVX2 is active afterwards. Both builds give identical results; this only
/// exists to measure one against the other.
pub fn set_avx2_enabled(enabled: bool) -> bool {
    AVX2.set(enabled)
}

/// `CPUID`/`XGETBV` probe for AVX2 with OS support of the YMM state.
fn detect_avx2() -> bool {
    const OSXSAVE: u32 = 1 << 27;
    const AVX: u32 = 1 << 28;
    const XCR0_SSE_AVX: u64 = 0b110;
    const AVX2: u32 = 1 << 5;
    if __cpuid(0).eax < 7 {
        return false;
    }
    let features = __cpuid(1).ecx;
    if features & OSXSAVE == 0 || features & AVX == 0 {
        return false;
    }
    // SAFETY: CPUID.1:ECX.OSXSAVE is set (checked above), so XGETBV is available and XCR0 readable.
    let xcr0 = unsafe { _xgetbv(0) };
    if xcr0 & XCR0_SSE_AVX != XCR0_SSE_AVX {
        return false;
    }
    __cpuid_count(7, 0).ebx & AVX2 != 0
}

/// `CPUID.(7,1):EAX.AVX-VNNI` (bit 4); the register state is the AVX one, checked by
/// `detect_avx2`, which every caller requires as well.
fn detect_avx_vnni() -> bool {
    const AVX_VNNI: u32 = 1 << 4;
    if __cpuid(0).eax < 7 || __cpuid_count(7, 0).eax < 1 {
        return false;
    }
    __cpuid_count(7, 1).eax & AVX_VNNI != 0
}
