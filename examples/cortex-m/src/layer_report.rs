//! Instructions per layer of the fully connected kernels at fixed shapes, int8 and int16
//! activations side by side, printed by the `kernels` image after its digest measurement (firmware
//! only; not built for the M0, whose 16 KiB of RAM hold the digest workload but not these
//! buffers as well):
//!
//! - `layer <name>: <instructions>` (mean over [`REPEATS`] calls) and `layer_macs <name>: <n>`
//!   for whole layers (e.g. `int16_lut16_256x256`: 256 x 256, int16 input, requantized to int16,
//!   interpolated table; `int8_lut_256x256` the int8 layer of the same shape), plus the
//!   accumulator-only forms (`*_acc_*`, no requantization) and `_extreme` variants on other data
//!   (equal counts show the kernels do not branch on values);
//! - `loop_per_mac <path>: <x>`: the marginal instructions per MAC of the DSP inner loop, the
//!   difference of two accumulator-only layers of 64 rows that differ only in width (so the
//!   per-row and per-call work cancels): `int8_pairs` / `int16_pairs` (inputs up to 256 columns,
//!   rewritten once into the pair buffer; 128 -> 256 columns), `int8_bytes` / `int16_halves`
//!   (wider inputs unpacked in the loop; 264 -> 504 columns);
//! - `layer_digest`: FNV-1a of every output, so that no call can be dropped.
//!
//! The weights (64 KiB), biases, requantization parameters and tables are deterministic constants
//! in flash; inputs and outputs live on the stack.

use cortex_m::peripheral::SYST;
use frmd_core::hash::Fnv1a64;
use frmd_core::kernels::{FcRequant, FullyConnected, KernelError, LayerInput, LUT16_LEN};

use crate::report::{self, report};
use crate::timer::{Calibration, TickCounter};

/// Calls per measured layer.
pub const REPEATS: u64 = 5;
const WEIGHT_COUNT: usize = 65_536;
const MAX_ROWS: usize = 256;
const MAX_WIDTH: usize = 1024;

#[repr(C, align(16))]
struct Aligned<T>(T);

/// One step of a 32-bit LCG (Numerical Recipes constants).
const fn lcg(state: u32) -> u32 {
    state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223)
}

static WEIGHTS: Aligned<[i8; WEIGHT_COUNT]> = Aligned({
    let mut out = [0_i8; WEIGHT_COUNT];
    let mut state = 0x5745_4947_u32;
    let mut i = 0;
    while i < WEIGHT_COUNT {
        state = lcg(state);
        let w = (state >> 24) as u8 as i8;
        out[i] = if w == i8::MIN { -127 } else { w };
        i += 1;
    }
    out
});

static BIAS32: [i32; MAX_ROWS] = {
    let mut out = [0_i32; MAX_ROWS];
    let mut state = 0x4249_4153_u32;
    let mut i = 0;
    while i < MAX_ROWS {
        state = lcg(state);
        out[i] = (state as i32) >> 12;
        i += 1;
    }
    out
};

static BIAS64: [i64; MAX_ROWS] = {
    let mut out = [0_i64; MAX_ROWS];
    let mut i = 0;
    while i < MAX_ROWS {
        out[i] = (BIAS32[i] as i64) << 8;
        i += 1;
    }
    out
};

static MULTIPLIERS: [i32; MAX_ROWS] = {
    let mut out = [0_i32; MAX_ROWS];
    let mut state = 0x4d55_4c54_u32;
    let mut i = 0;
    while i < MAX_ROWS {
        state = lcg(state);
        out[i] = (1 << 30) + (state >> 2) as i32;
        i += 1;
    }
    out
};

/// int8 outputs: real multipliers about 2^-12 (256 columns of int8 codes).
static SHIFTS8: [i32; MAX_ROWS] = [-11; MAX_ROWS];
/// int16 outputs: about 2^-14 (256 columns of int16 codes around 2^12).
static SHIFTS16: [i32; MAX_ROWS] = [-13; MAX_ROWS];

static LUT8: [i8; 256] = {
    let mut out = [0_i8; 256];
    let mut i = 0;
    while i < 256 {
        out[i] = ((i as i32 * 37) % 256 - 128) as i8;
        i += 1;
    }
    out
};

static LUT16: [i16; LUT16_LEN] = {
    let mut out = [0_i16; LUT16_LEN];
    let mut state = 0x4c55_5431_u32;
    let mut i = 0;
    while i < LUT16_LEN {
        state = lcg(state);
        out[i] = (state >> 16) as u16 as i16;
        i += 1;
    }
    out
};

/// What a measured layer computes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// int8 input, int8 output through the int8 table.
    Int8Lut,
    /// int16 input (the 16-bit first-layer plane), int8 output through the int8 table.
    Int8In16,
    /// int8 input, int32 accumulators only.
    Int8Acc,
    /// int16 input, int16 output through the interpolated table.
    Int16Lut,
    /// int16 input, int16 output, clamp only.
    Int16Clamp,
    /// int16 input, int64 accumulators only.
    Int16Acc,
}

struct Layer {
    name: &'static str,
    kind: Kind,
    width: usize,
    rows: usize,
    extreme: bool,
}

const fn layer(name: &'static str, kind: Kind, width: usize, rows: usize) -> Layer {
    Layer {
        name,
        kind,
        width,
        rows,
        extreme: false,
    }
}

const fn extreme(name: &'static str, kind: Kind, width: usize, rows: usize) -> Layer {
    Layer {
        name,
        kind,
        width,
        rows,
        extreme: true,
    }
}

const LAYERS: [Layer; 22] = [
    layer("int8_lut_256x256", Kind::Int8Lut, 256, 256),
    extreme("int8_lut_256x256_extreme", Kind::Int8Lut, 256, 256),
    layer("int16_lut16_256x256", Kind::Int16Lut, 256, 256),
    extreme("int16_lut16_256x256_extreme", Kind::Int16Lut, 256, 256),
    layer("int16_clamp_256x256", Kind::Int16Clamp, 256, 256),
    layer("int8_acc_256x256", Kind::Int8Acc, 256, 256),
    layer("int16_acc_256x256", Kind::Int16Acc, 256, 256),
    layer("int8in16_lut_40x256", Kind::Int8In16, 40, 256),
    layer("int16_lut16_40x256", Kind::Int16Lut, 40, 256),
    layer("int8_acc_256x42", Kind::Int8Acc, 256, 42),
    layer("int16_acc_256x42", Kind::Int16Acc, 256, 42),
    layer("int8_lut_512x128", Kind::Int8Lut, 512, 128),
    layer("int16_lut16_512x128", Kind::Int16Lut, 512, 128),
    layer("int16_lut16_1024x64", Kind::Int16Lut, 1024, 64),
    layer("int8_acc_128x64", Kind::Int8Acc, 128, 64),
    layer("int8_acc_256x64", Kind::Int8Acc, 256, 64),
    layer("int16_acc_128x64", Kind::Int16Acc, 128, 64),
    layer("int16_acc_256x64", Kind::Int16Acc, 256, 64),
    layer("int8_acc_264x64", Kind::Int8Acc, 264, 64),
    layer("int8_acc_504x64", Kind::Int8Acc, 504, 64),
    layer("int16_acc_264x64", Kind::Int16Acc, 264, 64),
    layer("int16_acc_504x64", Kind::Int16Acc, 504, 64),
];

/// `(path, narrow layer, wide layer)`: the marginal cost per MAC of the inner loop.
const LOOPS: [(&str, &str, &str); 4] = [
    ("int8_pairs", "int8_acc_128x64", "int8_acc_256x64"),
    ("int16_pairs", "int16_acc_128x64", "int16_acc_256x64"),
    ("int8_bytes", "int8_acc_264x64", "int8_acc_504x64"),
    ("int16_halves", "int16_acc_264x64", "int16_acc_504x64"),
];

/// Inputs and outputs of one measured call.
struct Buffers {
    input8: [i8; MAX_WIDTH],
    input16: Aligned<[i16; MAX_WIDTH]>,
    out8: [i8; MAX_ROWS],
    out16: [i16; MAX_ROWS],
    acc32: [i32; MAX_ROWS],
    acc64: [i64; MAX_ROWS],
}

impl Buffers {
    fn fill(&mut self, extreme: bool) {
        let mut state = 0x494e_5055_u32;
        for (x8, x16) in self.input8.iter_mut().zip(self.input16.0.iter_mut()) {
            state = lcg(state);
            if extreme {
                let high = state & (1 << 31) != 0;
                *x8 = if high { i8::MAX } else { i8::MIN };
                *x16 = if high { i16::MAX } else { i16::MIN };
            } else {
                *x8 = (state >> 24) as u8 as i8;
                // int16 codes of a hidden layer: mostly within +-2^12.
                *x16 = ((state >> 16) as u16 as i16) >> 3;
            }
        }
    }

    fn run(&mut self, layer: &Layer) -> Result<(), KernelError> {
        let (width, rows) = (layer.width, layer.rows);
        let weights = WEIGHTS.0.get(..width * rows).unwrap_or(&[]);
        let input8 = LayerInput::Int8(self.input8.get(..width).unwrap_or(&[]));
        let input16 = LayerInput::Int16(self.input16.0.get(..width).unwrap_or(&[]));
        let fc32 = FullyConnected::new(width, rows, weights, &BIAS32[..rows]);
        let fc64 = FullyConnected::new(width, rows, weights, &BIAS64[..rows]);
        let requant8 = FcRequant {
            multipliers: &MULTIPLIERS[..rows],
            shifts: &SHIFTS8[..rows],
            output_zero_point: -3,
            activation_min: i8::MIN,
            activation_max: i8::MAX,
        };
        let requant16 = FcRequant {
            multipliers: &MULTIPLIERS[..rows],
            shifts: &SHIFTS16[..rows],
            output_zero_point: 0,
            activation_min: i16::MIN,
            activation_max: i16::MAX,
        };
        match layer.kind {
            Kind::Int8Lut => {
                fc32.forward_activated(&requant8, Some(&LUT8), input8, &mut self.out8[..rows])
            }
            Kind::Int8In16 => {
                fc32.forward_activated(&requant8, Some(&LUT8), input16, &mut self.out8[..rows])
            }
            Kind::Int8Acc => fc32.accumulate(input8, &mut self.acc32[..rows]),
            Kind::Int16Lut => {
                fc64.forward_activated(&requant16, Some(&LUT16), input16, &mut self.out16[..rows])
            }
            Kind::Int16Clamp => {
                fc64.forward_activated(&requant16, None, input16, &mut self.out16[..rows])
            }
            Kind::Int16Acc => fc64.accumulate(input16, &mut self.acc64[..rows]),
        }
    }

    fn digest(&self, layer: &Layer, digest: &mut Fnv1a64) {
        let rows = layer.rows;
        match layer.kind {
            Kind::Int8Lut | Kind::Int8In16 => {
                for v in &self.out8[..rows] {
                    digest.bytes(&v.to_le_bytes());
                }
            }
            Kind::Int8Acc => {
                for v in &self.acc32[..rows] {
                    digest.bytes(&v.to_le_bytes());
                }
            }
            Kind::Int16Lut | Kind::Int16Clamp => {
                for v in &self.out16[..rows] {
                    digest.bytes(&v.to_le_bytes());
                }
            }
            Kind::Int16Acc => {
                for v in &self.acc64[..rows] {
                    digest.bytes(&v.to_le_bytes());
                }
            }
        }
    }
}

/// Measures every layer and prints the `layer`, `layer_macs`, `loop_per_mac` and
/// `layer_digest` lines. Not inlined, so its buffers are not part of the main measurement's
/// stack.
#[inline(never)]
pub fn layers(calibration: &Calibration) -> Result<(), KernelError> {
    let mut buffers = Buffers {
        input8: [0; MAX_WIDTH],
        input16: Aligned([0; MAX_WIDTH]),
        out8: [0; MAX_ROWS],
        out16: [0; MAX_ROWS],
        acc32: [0; MAX_ROWS],
        acc64: [0; MAX_ROWS],
    };
    let mut digest = Fnv1a64::new();
    let mut milli = [0_u64; LAYERS.len()];
    for (layer, result) in LAYERS.iter().zip(milli.iter_mut()) {
        buffers.fill(layer.extreme);
        let start = SYST::get_current();
        for _ in 0..REPEATS {
            buffers.run(core::hint::black_box(layer))?;
        }
        let end = SYST::get_current();
        let ticks = u64::from(TickCounter::elapsed(start, end));
        *result = calibration.instructions(ticks * 1000) / REPEATS;
        buffers.digest(layer, &mut digest);
        report!(
            "layer {}: {}.{:03}",
            layer.name,
            *result / 1000,
            *result % 1000
        );
        report!("layer_macs {}: {}", layer.name, layer.width * layer.rows);
    }
    let find = |name: &str| {
        LAYERS
            .iter()
            .zip(milli.iter())
            .find(|(layer, _)| layer.name == name)
            .map(|(layer, m)| (layer.width, layer.rows, *m))
    };
    for (path, narrow, wide) in LOOPS {
        if let (Some((w0, rows, m0)), Some((w1, _, m1))) = (find(narrow), find(wide)) {
            let macs = ((w1 - w0) * rows) as u64;
            // Thousandths of an instruction per MAC, rounded.
            let per_mac = (m1.saturating_sub(m0) + macs / 2) / macs.max(1);
            report!(
                "loop_per_mac {}: {}.{:03}",
                path,
                per_mac / 1000,
                per_mac % 1000
            );
        }
    }
    report::hex64("layer_digest", digest.finish());
    Ok(())
}
