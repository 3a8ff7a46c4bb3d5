//! The measured workload of the kernel firmware: frmd-core's fully connected kernels on random
//! shapes, so that every path of the Cortex-M DSP kernels (two-row pairs, the four-step loop
//! entered at each remainder, column tails, an odd last row, inputs wider than the pair buffer,
//! rows off word boundaries, int8 and int16 inputs, every clamp and shift; for int16 activations
//! also the in-loop int16 unpacking, the 512-column int64 chunks, wrapping chunk sums, the Q15
//! requantization and the interpolated tables) meets the host's portable (and AVX2) kernels on
//! the same bytes.
//!
//! `core` + frmd-core only; the host test runs the same cases and must reproduce the digest.
//!
//! Cases `0..INT8_CASES`, int8 activations: case `c` draws from `Rng::new(SEED + c)`: the width
//! (`1..=300`, every fifth case a multiple of 8, every seventh above 256), the rows (`1..=9`), the
//! weights (every fourth case only `-127` and `127`), biases (24-bit), per-row requantization
//! (shifts `-12..=3`, one case in six with a narrow clamp), the input (int8, or int16 for odd
//! cases) and whether a table is applied; the weights start `c % 4` bytes into a word-aligned
//! buffer. Digest per case: the requantized int8 outputs, then the raw accumulators (int8 inputs
//! only) as little-endian i32. (These are the 48 cases of the int8-only workload, unchanged: their
//! digest alone is [`INT8_DIGEST`].)
//!
//! Cases `INT8_CASES..CASES`, int16 activations (the 16x8 scheme: `FullyConnected<i64>`,
//! `FcRequant<i16>`, `Lut16`): case `INT8_CASES + k` draws from `Rng::new(SEED16 + k)`: the width
//! by `k % 6` (multiples of 8 up to 256, anything up to 256, 264..=511 with every remainder mod 8,
//! 513..=1100, multiples of
//! 8 in 520..=1096, and the boundaries 256/257/511/512/513/1024/1025/1100), up to 17 rows (a
//! second 16-row block) within [`WEIGHT16_BYTES`], weights uniform in `[-127, 127]`, only
//! `+-127`, uniform in `[-128, 127]`, or all `-128` against inputs all `-32768` (every full
//! chunk's sum wraps to `-2^31`), inputs at the int16 ends or random, int64 biases from 0 to
//! `+-2^46`, shifts around the accumulators' spread with cases at `-31` and `7`, full / ReLU / narrow / single-value
//! clamps, a random interpolated table in two of three cases, weights off word boundaries in one
//! case of eight and a misaligned int16 input in another, int8 codes as the input in one case of
//! sixteen. Digest per case: the int16 outputs (LE i16), the int64 accumulators (LE i64) and their
//! dequantized f32 values (LE bits).

use frmd_core::hash::Fnv1a64;
use frmd_core::kernels::{
    dequantize_accumulators, FcRequant, FullyConnected, KernelError, LayerInput, Lut16, Lut8,
    LUT16_LEN,
};
use frmd_core::quant::{BIAS16_MAX, SHIFT16_MAX, SHIFT16_MIN};
use frmd_core::rng::Rng;

use crate::workload::Workload;

/// Distinct cases: the int8 ones, then as many int16 ones.
pub const CASES: usize = 2 * INT8_CASES;
/// The int8-activation cases (case numbers `0..INT8_CASES`).
pub const INT8_CASES: usize = 48;
/// Seed of case 0; case `c` uses `SEED + c`.
pub const SEED: u64 = 0x4652_4D44_4B45_524E;
/// Seed of int16 case 0 (case `INT8_CASES`); int16 case `k` uses `SEED16 + k`.
pub const SEED16: u64 = 0x4652_4D44_3136_4B45;
/// Widest input and most rows of an int8 case.
pub const MAX_WIDTH: usize = 300;
pub const MAX_ROWS: usize = 9;
/// Widest input and most rows of an int16 case; `rows * width <= WEIGHT16_BYTES`.
pub const MAX_WIDTH16: usize = 1100;
pub const MAX_ROWS16: usize = 17;
/// Weight bytes of an int16 case (the buffer is shared with the int8 cases; the M0's 16 KiB of
/// RAM bound it).
pub const WEIGHT16_BYTES: usize = 5600;
/// The digest of the int8 cases alone: the workload's digest before the int16 cases were added
/// (main at `433216a`), which the host test checks so that the int8 kernels' bits are unchanged.
pub const INT8_DIGEST: u64 = 0xea1b_1b95_c686_3eb2;

const WEIGHT_BYTES: usize = if MAX_WIDTH * MAX_ROWS > WEIGHT16_BYTES {
    MAX_WIDTH * MAX_ROWS
} else {
    WEIGHT16_BYTES
};

/// Word-aligned weight storage (a case starts 0..3 bytes into it).
#[repr(C, align(4))]
struct Weights([i8; WEIGHT_BYTES + 4]);

/// Word-aligned int16 input storage (a case may start one halfword into it).
#[repr(C, align(4))]
struct Halves([i16; MAX_WIDTH16 + 2]);

/// The data of one int16 case that the int8 cases do not have.
struct Int16Case {
    rows: usize,
    input_offset: usize,
    int8_input: bool,
    clamp: (i16, i16),
    bias: [i64; MAX_ROWS16],
    multipliers: [i32; MAX_ROWS16],
    shifts: [i32; MAX_ROWS16],
    scales: [f32; MAX_ROWS16],
    table: Lut16,
    output: [i16; MAX_ROWS16],
    accumulators: [i64; MAX_ROWS16],
    dequantized: [f32; MAX_ROWS16],
}

/// One case's data and outputs.
pub struct KernelWorkload {
    case: usize,
    width: usize,
    rows: usize,
    offset: usize,
    wide: bool,
    with_table: bool,
    clamp: (i8, i8),
    zero_point: i32,
    weights: Weights,
    bias: [i32; MAX_ROWS],
    multipliers: [i32; MAX_ROWS],
    shifts: [i32; MAX_ROWS],
    input: [i8; MAX_WIDTH16],
    input_wide: Halves,
    table: Lut8,
    output: [i8; MAX_ROWS],
    accumulators: [i32; MAX_ROWS],
    int16: Int16Case,
}

impl KernelWorkload {
    pub fn new() -> Self {
        Self {
            case: 0,
            width: 1,
            rows: 1,
            offset: 0,
            wide: false,
            with_table: false,
            clamp: (i8::MIN, i8::MAX),
            zero_point: 0,
            weights: Weights([0; WEIGHT_BYTES + 4]),
            bias: [0; MAX_ROWS],
            multipliers: [0; MAX_ROWS],
            shifts: [0; MAX_ROWS],
            input: [0; MAX_WIDTH16],
            input_wide: Halves([0; MAX_WIDTH16 + 2]),
            table: Lut8::from_table([0; 256]),
            output: [0; MAX_ROWS],
            accumulators: [0; MAX_ROWS],
            int16: Int16Case {
                rows: 1,
                input_offset: 0,
                int8_input: false,
                clamp: (i16::MIN, i16::MAX),
                bias: [0; MAX_ROWS16],
                multipliers: [0; MAX_ROWS16],
                shifts: [0; MAX_ROWS16],
                scales: [0.0; MAX_ROWS16],
                table: Lut16::from_table([0; LUT16_LEN]),
                output: [0; MAX_ROWS16],
                accumulators: [0; MAX_ROWS16],
                dequantized: [0.0; MAX_ROWS16],
            },
        }
    }

    fn layer(&self) -> FullyConnected<'_> {
        let weights = self
            .weights
            .0
            .get(self.offset..self.offset + self.width * self.rows)
            .unwrap_or(&[]);
        FullyConnected::new(self.width, self.rows, weights, &self.bias[..self.rows])
    }

    /// Whether the prepared case is an int16-activation case.
    pub fn is_int16(&self) -> bool {
        self.case >= INT8_CASES
    }

    /// Input width of the prepared case.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Output rows of the prepared case.
    pub fn rows(&self) -> usize {
        if self.is_int16() {
            self.int16.rows
        } else {
            self.rows
        }
    }

    /// Whether the prepared int16 case's weights start on a word boundary and its input is
    /// word-aligned (the DSP kernels' assembly paths; others take the portable rows).
    pub fn aligned(&self) -> bool {
        self.offset == 0 && self.int16.input_offset == 0
    }

    /// The prepared case's weights.
    pub fn weights(&self) -> &[i8] {
        let rows = self.rows();
        self.weights
            .0
            .get(self.offset..self.offset + self.width * rows)
            .unwrap_or(&[])
    }

    /// The prepared int16 case's int16 input.
    pub fn input16(&self) -> &[i16] {
        let start = self.int16.input_offset;
        self.input_wide
            .0
            .get(start..start + self.width)
            .unwrap_or(&[])
    }

    /// The prepared int16 case's outputs (after [`Workload::run`]).
    pub fn output16(&self) -> &[i16] {
        &self.int16.output[..self.int16.rows]
    }

    fn prepare_int8(&mut self, case: usize) {
        let mut rng = Rng::new(SEED.wrapping_add(case as u64));
        let mut draw = |n: u32| (rng.next_u32() % n) as usize;
        self.width = match case {
            c if c % 7 == 3 => 257 + draw(44),
            c if c % 5 == 0 => 8 * (1 + draw(32)),
            _ => 1 + draw(MAX_WIDTH as u32),
        };
        self.rows = 1 + draw(MAX_ROWS as u32);
        self.offset = case % 4;
        self.wide = case % 2 == 1;
        self.with_table = case % 3 != 0;
        self.clamp = if case % 6 == 5 {
            (-20, 35)
        } else {
            (i8::MIN, i8::MAX)
        };
        self.zero_point = draw(256) as i32 - 128;
        let extreme = case % 4 == 2;
        for w in self.weights.0.iter_mut().take(MAX_WIDTH * MAX_ROWS + 4) {
            let bits = rng.next_u32();
            *w = match (extreme, bits & 1) {
                (true, 0) => -127,
                (true, _) => 127,
                (false, _) => ((bits >> 8) as i8).max(-127),
            };
        }
        for o in 0..MAX_ROWS {
            self.bias[o] = (rng.next_u32() as i32) >> 8;
            self.multipliers[o] = (1 << 30) + (rng.next_u32() >> 2) as i32;
            self.shifts[o] = (rng.next_u32() % 16) as i32 - 12;
        }
        for (x, x_wide) in self.input[..MAX_WIDTH]
            .iter_mut()
            .zip(self.input_wide.0.iter_mut())
        {
            let bits = rng.next_u32();
            *x = bits as i8;
            *x_wide = (bits >> 16) as i16;
        }
        for (i, entry) in self.table.table.iter_mut().enumerate() {
            *entry = (i as i32 * 37 % 256 - 128) as i8;
        }
    }

    fn run_int8(&mut self) -> Result<(), KernelError> {
        let requant = FcRequant {
            multipliers: &self.multipliers[..self.rows],
            shifts: &self.shifts[..self.rows],
            output_zero_point: self.zero_point,
            activation_min: self.clamp.0,
            activation_max: self.clamp.1,
        };
        let table = if self.with_table {
            Some(&self.table.table)
        } else {
            None
        };
        let layer = self.layer();
        let input = if self.wide {
            LayerInput::Int16(&self.input_wide.0[..self.width])
        } else {
            LayerInput::Int8(&self.input[..self.width])
        };
        let mut output = [0_i8; MAX_ROWS];
        layer.forward_activated(&requant, table, input, &mut output[..self.rows])?;
        let mut accumulators = [0_i32; MAX_ROWS];
        if !self.wide {
            layer
                .forward_accumulators(&self.input[..self.width], &mut accumulators[..self.rows])?;
        }
        self.output = output;
        self.accumulators = accumulators;
        Ok(())
    }
}

impl Default for KernelWorkload {
    fn default() -> Self {
        Self::new()
    }
}

impl Workload for KernelWorkload {
    type Error = KernelError;

    fn name(&self) -> &'static str {
        "fully connected kernels on random shapes (int8 and int16 activations, int8 and int16 inputs)"
    }

    fn cases(&self) -> usize {
        CASES
    }

    fn prepare(&mut self, case: usize) -> Result<(), KernelError> {
        self.case = case;
        if case < INT8_CASES {
            self.prepare_int8(case);
        } else {
            self.prepare_int16(case - INT8_CASES);
        }
        Ok(())
    }

    fn run(&mut self) -> Result<(), KernelError> {
        if self.is_int16() {
            self.run_int16()
        } else {
            self.run_int8()
        }
    }

    fn digest_outputs(&self, digest: &mut Fnv1a64) {
        if self.is_int16() {
            let case = &self.int16;
            let rows = case.rows;
            for value in &case.output[..rows] {
                digest.bytes(&value.to_le_bytes());
            }
            for value in &case.accumulators[..rows] {
                digest.bytes(&value.to_le_bytes());
            }
            for value in &case.dequantized[..rows] {
                digest.bytes(&value.to_bits().to_le_bytes());
            }
            return;
        }
        for value in &self.output[..self.rows] {
            digest.bytes(&value.to_le_bytes());
        }
        if !self.wide {
            for value in &self.accumulators[..self.rows] {
                digest.bytes(&value.to_le_bytes());
            }
        }
    }
}

mod int16;
pub use int16::Int16Coverage;
