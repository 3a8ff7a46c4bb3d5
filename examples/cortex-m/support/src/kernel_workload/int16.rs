//! The int16-activation half of the kernel workload: its layer view, how a case is drawn, the
//! run, and (with `std`) the comparison with frmd-core's wide-integer model.
use super::*;

impl KernelWorkload {
    pub(super) fn layer16(&self) -> FullyConnected<'_, i64> {
        let rows = self.int16.rows;
        let weights = self
            .weights
            .0
            .get(self.offset..self.offset + self.width * rows)
            .unwrap_or(&[]);
        FullyConnected::new(self.width, rows, weights, &self.int16.bias[..rows])
    }

    pub(super) fn prepare_int16(&mut self, k: usize) {
        const BOUNDARIES: [usize; 8] = [256, 257, 511, 512, 513, 1024, 1025, 1100];
        let mut rng = Rng::new(SEED16.wrapping_add(k as u64));
        let mut draw = |n: usize| (rng.next_u32() % n as u32) as usize;
        self.width = match k % 6 {
            0 => 8 * (1 + draw(32)),
            1 => 1 + draw(256),
            // 264..=511, every remainder mod 8 over the eight such cases.
            2 => 264 + 8 * draw(31) + (k / 6) % 8,
            3 => 513 + draw(MAX_WIDTH16 - 512),
            4 => 8 * (65 + draw(73)),
            _ => BOUNDARIES[(k / 6) % BOUNDARIES.len()],
        };
        let most_rows = (WEIGHT16_BYTES / self.width).clamp(1, MAX_ROWS16);
        // Cases 0 and 1 mod 12 (at most 256 columns) fill 17 rows: a second 16-row block.
        let rows = if k % 12 < 2 {
            most_rows
        } else {
            1 + draw(most_rows)
        };
        self.offset = if k % 8 == 5 { 1 + k % 3 } else { 0 };
        let case = &mut self.int16;
        case.rows = rows;
        case.input_offset = usize::from(k % 8 == 6);
        case.int8_input = k % 16 == 15;
        self.with_table = k % 3 != 0;
        case.clamp = match k % 12 {
            4 | 10 => (0, i16::MAX),
            5 | 11 => (-1000, 5000),
            7 => (7, 7),
            _ => (i16::MIN, i16::MAX),
        };
        // 1: all -128 against all -32768 (wrapping chunk sums); 2, 6: +-127; 3: [-128, 127].
        let kind = k % 8;
        for w in self.weights.0.iter_mut().take(WEIGHT16_BYTES + 4) {
            let bits = rng.next_u32();
            *w = match kind {
                1 => i8::MIN,
                2 | 6 if bits & 1 == 0 => -127,
                2 | 6 => 127,
                3 => (bits >> 8) as i8,
                _ => ((bits >> 8) as i8).max(-127),
            };
        }
        for x in self.input_wide.0.iter_mut() {
            let bits = rng.next_u32();
            *x = match (kind, k % 3, bits & 3) {
                (1, _, _) => i16::MIN,
                (_, 0, 0) => i16::MIN,
                (_, 0, 1) => i16::MAX,
                (_, 1, _) => (bits >> 16) as i16 >> (bits % 12),
                _ => (bits >> 16) as i16,
            };
        }
        for (x, wide) in self.input.iter_mut().zip(self.input_wide.0.iter()) {
            *x = (*wide >> 8) as i8;
        }
        let octaves = usize::BITS - self.width.leading_zeros();
        for r in 0..MAX_ROWS16 {
            let bits = rng.next_u32();
            case.bias[r] = match (k + r) % 9 {
                0 => BIAS16_MAX,
                1 => -BIAS16_MAX,
                2 => 0,
                3 => (i64::from(bits as i32) << 15) >> (bits % 16),
                _ => i64::from(bits as i32) >> 5,
            };
            case.multipliers[r] = (1 << 30) + (rng.next_u32() >> 2) as i32;
            case.shifts[r] = match (k + r) % 10 {
                8 => SHIFT16_MIN,
                9 => SHIFT16_MAX,
                // Around the accumulators' spread (about 2^21 sqrt(width)), so that outputs
                // cover the int16 range and some saturate.
                _ => -6 - (octaves / 2) as i32 - (rng.next_u32() % 7) as i32,
            };
            // Dequantization scales over many octaves.
            let mantissa = 1.0 + (rng.next_u32() >> 9) as f32 / (1 << 23) as f32;
            case.scales[r] = mantissa / (1_u64 << (20 + rng.next_u32() % 24)) as f32;
        }
        for t in case.table.table.iter_mut() {
            *t = rng.next_u32() as i16;
        }
    }

    pub(super) fn run_int16(&mut self) -> Result<(), KernelError> {
        let case = &self.int16;
        let rows = case.rows;
        let requant = FcRequant::<i16> {
            multipliers: &case.multipliers[..rows],
            shifts: &case.shifts[..rows],
            output_zero_point: 0,
            activation_min: case.clamp.0,
            activation_max: case.clamp.1,
        };
        let table = if self.with_table {
            Some(&case.table.table)
        } else {
            None
        };
        let input = if case.int8_input {
            LayerInput::Int8(&self.input[..self.width])
        } else {
            LayerInput::Int16(self.input16())
        };
        let layer = self.layer16();
        let mut output = [0_i16; MAX_ROWS16];
        layer.forward_activated(&requant, table, input, &mut output[..rows])?;
        let mut accumulators = [0_i64; MAX_ROWS16];
        layer.accumulate(input, &mut accumulators[..rows])?;
        let mut dequantized = [0.0_f32; MAX_ROWS16];
        dequantize_accumulators(
            &accumulators[..rows],
            &case.scales[..rows],
            &mut dequantized[..rows],
        )?;
        let case = &mut self.int16;
        case.output = output;
        case.accumulators = accumulators;
        case.dequantized = dequantized;
        Ok(())
    }
}

/// What the int16 cases reach (for the host test's coverage checks).
#[derive(Clone, Copy, Debug, Default)]
pub struct Int16Coverage {
    /// Rows whose accumulator differs from the exact `bias + w . x` (a chunk sum wrapped).
    pub wrapped_rows: usize,
    /// Outputs strictly inside the clamp range.
    pub unclamped: usize,
    /// Outputs at a clamp bound.
    pub clamped: usize,
}

#[cfg(feature = "std")]
impl KernelWorkload {
    /// (Host) the prepared and run int16 case against frmd-core's wide-integer model
    /// (`frmd_core::quant::reference`: chunk residues, i128 requantization, the slope-form
    /// lookup, the Euclidean dequantization split); `Err` names the first difference.
    pub fn int16_against_model(&self) -> Result<Int16Coverage, std::string::String> {
        use frmd_core::quant::{reference, CHUNK16};
        let case = &self.int16;
        let mut coverage = Int16Coverage::default();
        let rows = self.weights().chunks_exact(self.width).take(case.rows);
        for (r, row) in rows.enumerate() {
            let bias = case.bias[r];
            let (acc, exact) = if case.int8_input {
                let input = &self.input[..self.width];
                let acc = reference::accumulate_chunked(bias, row, input, CHUNK16);
                (
                    acc,
                    reference::accumulate_chunked(bias, row, input, usize::MAX),
                )
            } else {
                let input = self.input16();
                let acc = reference::accumulate_chunked(bias, row, input, CHUNK16);
                let exact: i128 = i128::from(bias)
                    + row
                        .iter()
                        .zip(input)
                        .map(|(w, x)| i128::from(*w) * i128::from(*x))
                        .sum::<i128>();
                (acc, exact)
            };
            coverage.wrapped_rows += usize::from(acc != exact);
            if i128::from(case.accumulators[r]) != acc {
                return Err(std::format!(
                    "row {r}: accumulator {} vs model {acc}",
                    case.accumulators[r]
                ));
            }
            let (lo, hi) = case.clamp;
            let q = reference::requantize16(acc, case.multipliers[r], case.shifts[r], lo, hi);
            if q == lo || q == hi {
                coverage.clamped += 1;
            } else {
                coverage.unclamped += 1;
            }
            let want = if self.with_table {
                reference::lookup16(&case.table.table, q).ok_or("table too short")?
            } else {
                q
            };
            if case.output[r] != want {
                return Err(std::format!(
                    "row {r}: output {} vs model {want}",
                    case.output[r]
                ));
            }
            let acc = i64::try_from(acc).map_err(|_| "accumulator beyond i64")?;
            let value = reference::dequantize_wide(acc, case.scales[r]);
            if case.dequantized[r].to_bits() != value.to_bits() {
                return Err(std::format!(
                    "row {r}: dequantized {} vs model {value}",
                    case.dequantized[r]
                ));
            }
        }
        Ok(coverage)
    }
}
