//! The measured workload.
//!
//! PLACEHOLDER until `frmd_core::prodmp::BakedProDmp` lands: a 12 x 21 f32 matrix-vector product
//! (the shape of a 12-step, 20-basis ProDMP position table), so that the timing, digest and memory
//! plumbing can be exercised end to end.

use crate::digest::Fnv1a64;

pub const NAME: &str = "placeholder-matvec-12x21";
/// Number of distinct inputs; each is decoded [`REPEATS`] times.
pub const CASES: usize = 8;
pub const REPEATS: usize = 5;

const ROWS: usize = 12;
const COLS: usize = 21;

pub struct Workload {
    table: [[f32; COLS]; ROWS],
    input: [f32; COLS],
    output: [f32; ROWS],
}

/// A deterministic value in [-1, 1] for (`a`, `b`), exactly representable in f32.
fn fixed_value(a: usize, b: usize) -> f32 {
    let mixed = (a as u32).wrapping_mul(2_654_435_761) ^ (b as u32).wrapping_mul(40_503);
    ((mixed % 2001) as f32 - 1000.0) / 1000.0
}

impl Workload {
    pub fn new() -> Result<Self, &'static str> {
        let mut table = [[0.0; COLS]; ROWS];
        for (row_index, row) in table.iter_mut().enumerate() {
            for (col_index, value) in row.iter_mut().enumerate() {
                *value = fixed_value(row_index + 1000, col_index);
            }
        }
        Ok(Self { table, input: [0.0; COLS], output: [0.0; ROWS] })
    }

    /// Loads input number `case` (not measured).
    pub fn prepare(&mut self, case: usize) {
        for (index, value) in self.input.iter_mut().enumerate() {
            *value = fixed_value(case, index);
        }
    }

    /// The measured call.
    pub fn run(&mut self) -> Result<(), &'static str> {
        let input = core::hint::black_box(&self.input);
        for (out, row) in self.output.iter_mut().zip(self.table.iter()) {
            *out = row.iter().zip(input.iter()).map(|(a, b)| a * b).sum();
        }
        Ok(())
    }

    /// Feeds the outputs of the last [`Self::run`] to `digest`.
    pub fn digest_outputs(&self, digest: &mut Fnv1a64) {
        digest.f32s(&self.output);
    }
}
