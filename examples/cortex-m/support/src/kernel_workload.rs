//! The measured workload of the kernel firmware: frmd-core's fully connected kernels on random
//! shapes, so that every path of the Cortex-M DSP kernels (two-row pairs, the four-step loop
//! entered at each remainder, column tails, an odd last row, inputs wider than the pair buffer,
//! rows off word boundaries, int8 and int16 inputs, every clamp and shift) meets the host's
//! portable (and AVX2) kernels on the same bytes.
//!
//! `core` + frmd-core only; the host test runs the same cases and must reproduce the digest.
//!
//! Case `c` draws from `Rng::new(SEED + c)`: the width (`1..=300`, every fifth case a multiple
//! of 8, every seventh above 256), the rows (`1..=9`), the weights (every fourth case only
//! `-127` and `127`), biases (24-bit), per-row requantization (shifts `-12..=3`, one case in six
//! with a narrow clamp), the input (int8, or int16 for odd cases) and whether a table is applied;
//! the weights start `c % 4` bytes into a word-aligned buffer. Digest per case: the requantized
//! int8 outputs, then the raw accumulators (int8 inputs only) as little-endian i32.

use frmd_core::hash::Fnv1a64;
use frmd_core::kernels::{FcRequant, FullyConnected, KernelError, LayerInput, Lut8};
use frmd_core::rng::Rng;

use crate::workload::Workload;

/// Distinct cases.
pub const CASES: usize = 48;
/// Seed of case 0; case `c` uses `SEED + c`.
pub const SEED: u64 = 0x4652_4D44_4B45_524E;
/// Widest input and most rows of a case.
pub const MAX_WIDTH: usize = 300;
pub const MAX_ROWS: usize = 9;

/// Word-aligned weight storage (a case starts 0..3 bytes into it).
#[repr(C, align(4))]
struct Weights([i8; MAX_WIDTH * MAX_ROWS + 4]);

/// One case's data and outputs.
pub struct KernelWorkload {
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
    input: [i8; MAX_WIDTH],
    input_wide: [i16; MAX_WIDTH],
    table: Lut8,
    output: [i8; MAX_ROWS],
    accumulators: [i32; MAX_ROWS],
}

impl KernelWorkload {
    pub fn new() -> Self {
        Self {
            width: 1,
            rows: 1,
            offset: 0,
            wide: false,
            with_table: false,
            clamp: (i8::MIN, i8::MAX),
            zero_point: 0,
            weights: Weights([0; MAX_WIDTH * MAX_ROWS + 4]),
            bias: [0; MAX_ROWS],
            multipliers: [0; MAX_ROWS],
            shifts: [0; MAX_ROWS],
            input: [0; MAX_WIDTH],
            input_wide: [0; MAX_WIDTH],
            table: Lut8::from_table([0; 256]),
            output: [0; MAX_ROWS],
            accumulators: [0; MAX_ROWS],
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
}

impl KernelWorkload {
    /// Input width of the prepared case.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Output rows of the prepared case.
    pub fn rows(&self) -> usize {
        self.rows
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
        "fully connected kernels on random shapes (int8 and int16 inputs)"
    }

    fn cases(&self) -> usize {
        CASES
    }

    fn prepare(&mut self, case: usize) -> Result<(), KernelError> {
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
        for w in self.weights.0.iter_mut() {
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
        for (x, x_wide) in self.input.iter_mut().zip(self.input_wide.iter_mut()) {
            let bits = rng.next_u32();
            *x = bits as i8;
            *x_wide = (bits >> 16) as i16;
        }
        for (i, entry) in self.table.table.iter_mut().enumerate() {
            *entry = (i as i32 * 37 % 256 - 128) as i8;
        }
        Ok(())
    }

    fn run(&mut self) -> Result<(), KernelError> {
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
            LayerInput::Int16(&self.input_wide[..self.width])
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

    fn digest_outputs(&self, digest: &mut Fnv1a64) {
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
