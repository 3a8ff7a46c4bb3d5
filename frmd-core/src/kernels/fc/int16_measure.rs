//! (Measurements, `--ignored`) the 256x256 int8 and int16 layers with table on the host: wall
//! time per path and a callgrind harness. The exactness tests are `int16_tests`.

extern crate std;

use super::*;
use crate::kernels::lut16::Lut16Table;
use crate::kernels::LutTable;
use crate::rng::SplitMix64;
use std::{vec, vec::Vec};

/// One 256x256 layer's weights, biases, requantization and inputs at both activation widths.
struct Layers {
    width: usize,
    rows: usize,
    weights: Vec<i8>,
    bias32: Vec<i32>,
    bias64: Vec<i64>,
    multipliers: Vec<i32>,
    shifts8: Vec<i32>,
    shifts16: Vec<i32>,
    input8: Vec<i8>,
    input16: Vec<i16>,
    lut8: LutTable,
    lut16: Lut16Table,
}

impl Layers {
    fn new() -> Self {
        let (width, rows) = (256, 256);
        let mut rng = SplitMix64::new(0x7133);
        let weights = (0..width * rows)
            .map(|_| ((rng.next_u64() >> 8) as i8).max(-127))
            .collect();
        let bias32: Vec<i32> = (0..rows).map(|_| (rng.next_u64() as i32) >> 12).collect();
        let bias64 = bias32.iter().map(|b| i64::from(*b) << 8).collect();
        let input8 = (0..width).map(|_| rng.next_u64() as i8).collect();
        let input16 = (0..width).map(|_| (rng.next_u64() as i16) >> 3).collect();
        Layers {
            width,
            rows,
            weights,
            bias32,
            bias64,
            multipliers: vec![1 << 30; rows],
            shifts8: vec![-11; rows],
            shifts16: vec![-13; rows],
            input8,
            input16,
            lut8: core::array::from_fn(|i| i as u8 as i8),
            lut16: core::array::from_fn(|i| (i as i16).wrapping_mul(61)),
        }
    }

    fn fc32(&self) -> FullyConnected<'_> {
        FullyConnected::new(self.width, self.rows, &self.weights, &self.bias32)
    }

    fn fc64(&self) -> FullyConnected<'_, i64> {
        FullyConnected::new(self.width, self.rows, &self.weights, &self.bias64)
    }

    fn requant8(&self) -> FcRequant<'_> {
        FcRequant {
            multipliers: &self.multipliers,
            shifts: &self.shifts8,
            output_zero_point: 0,
            activation_min: i8::MIN,
            activation_max: i8::MAX,
        }
    }

    fn requant16(&self) -> FcRequant<'_, i16> {
        FcRequant {
            multipliers: &self.multipliers,
            shifts: &self.shifts16,
            output_zero_point: 0,
            activation_min: i16::MIN,
            activation_max: i16::MAX,
        }
    }
}

/// Host time of the 256x256 layer with table, int8 against int16, AVX2 (when present) and
/// portable: the minimum over many calls, so load on the machine matters less.
#[test]
#[ignore]
fn host_layer_timings() {
    use std::time::Instant;
    let l = Layers::new();
    let (fc32, fc64, requant8, requant16) = (l.fc32(), l.fc64(), l.requant8(), l.requant16());
    let (input8, input16) = (&l.input8, &l.input16);
    let (mut out8, mut out16) = (vec![0_i8; l.rows], vec![0_i16; l.rows]);
    let time = |f: &mut dyn FnMut()| {
        let mut best = f64::MAX;
        for _ in 0..200 {
            let start = Instant::now();
            for _ in 0..20 {
                f();
            }
            best = best.min(start.elapsed().as_secs_f64() / 20.0);
        }
        best * 1e9
    };
    for avx2 in [true, false] {
        crate::kernels::x86::set_avx2_enabled(avx2);
        let int8 = time(&mut || {
            fc32.forward_activated(
                &requant8,
                Some(&l.lut8),
                LayerInput::Int8(input8),
                &mut out8,
            )
            .unwrap()
        });
        let int16 = time(&mut || {
            fc64.forward_activated(
                &requant16,
                Some(&l.lut16),
                LayerInput::Int16(input16),
                &mut out16,
            )
            .unwrap()
        });
        let int8_plain = time(&mut || {
            fc32.forward_activated(&requant8, None, LayerInput::Int8(input8), &mut out8)
                .unwrap()
        });
        let int16_plain = time(&mut || {
            fc64.forward_activated(&requant16, None, LayerInput::Int16(input16), &mut out16)
                .unwrap()
        });
        let (mut acc32, mut acc64) = (vec![0_i32; l.rows], vec![0_i64; l.rows]);
        let int8_acc = time(&mut || {
            fc32.accumulate(LayerInput::Int8(input8), &mut acc32)
                .unwrap()
        });
        let int16_acc = time(&mut || {
            fc64.accumulate(LayerInput::Int16(input16), &mut acc64)
                .unwrap()
        });
        std::eprintln!(
            "256x256, AVX2 {avx2}: with table int8 {int8:.0} ns, int16 {int16:.0} ns ({:.2}x); \
             without table {int8_plain:.0} / {int16_plain:.0} ns; accumulators only {int8_acc:.0} / {int16_acc:.0} ns",
            int16 / int8
        );
    }
    crate::kernels::x86::set_avx2_enabled(true);
}

/// (For callgrind) 1000 calls of the 256x256 int8 and int16 layers with table on the active host
/// path, each in a function of its own
/// (`valgrind --tool=callgrind --collect-atstart=no --toggle-collect='*layer_calls_*'`).
#[test]
#[ignore]
fn host_layer_instructions() {
    #[inline(never)]
    fn layer_calls_int8(
        fc: &FullyConnected<'_>,
        r: &FcRequant<'_>,
        t: &LutTable,
        x: &[i8],
        out: &mut [i8],
    ) {
        for _ in 0..1000 {
            fc.forward_activated(r, Some(t), LayerInput::Int8(core::hint::black_box(x)), out)
                .unwrap();
        }
    }
    #[inline(never)]
    fn layer_calls_int16(
        fc: &FullyConnected<'_, i64>,
        r: &FcRequant<'_, i16>,
        t: &Lut16Table,
        x: &[i16],
        out: &mut [i16],
    ) {
        for _ in 0..1000 {
            fc.forward_activated(r, Some(t), LayerInput::Int16(core::hint::black_box(x)), out)
                .unwrap();
        }
    }
    let l = Layers::new();
    let (mut out8, mut out16) = (vec![0_i8; l.rows], vec![0_i16; l.rows]);
    layer_calls_int8(&l.fc32(), &l.requant8(), &l.lut8, &l.input8, &mut out8);
    layer_calls_int16(&l.fc64(), &l.requant16(), &l.lut16, &l.input16, &mut out16);
    std::eprintln!(
        "avx2 {} outputs {} {}",
        crate::kernels::x86::avx2_active(),
        out8[0],
        out16[0]
    );
}
