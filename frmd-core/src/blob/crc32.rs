//! CRC-32 (IEEE 802.3, the zlib/PNG/Ethernet CRC): reflected polynomial `0xEDB88320`, initial
//! value and final XOR `0xFFFFFFFF`, with a 256-entry table built at compile time (1 KiB flash).

/// Reflected IEEE polynomial.
const POLYNOMIAL: u32 = 0xEDB8_8320;

// Evaluated at compile time only: an out-of-range index would be a build error, not a panic.
#[allow(clippy::indexing_slicing)]
const fn build_table() -> [u32; 256] {
    let mut table = [0_u32; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut crc = byte as u32;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ POLYNOMIAL
            } else {
                crc >> 1
            };
            bit += 1;
        }
        table[byte] = crc;
        byte += 1;
    }
    table
}

static TABLE: [u32; 256] = build_table();

/// Incremental CRC-32 (`update` any number of times, then `finish`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crc32 {
    state: u32,
}

impl Crc32 {
    /// Fresh state.
    pub const fn new() -> Self {
        Self { state: u32::MAX }
    }

    /// Feeds `data`.
    pub fn update(&mut self, data: &[u8]) {
        for byte in data {
            let index = usize::from((self.state as u8) ^ byte);
            let entry = TABLE.get(index).copied().unwrap_or(0);
            self.state = (self.state >> 8) ^ entry;
        }
    }

    /// The CRC of everything fed so far.
    pub fn finish(&self) -> u32 {
        !self.state
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

/// CRC-32 of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = Crc32::new();
    crc.update(data);
    crc.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-by-bit reference (no table).
    fn crc32_bitwise(data: &[u8]) -> u32 {
        let mut crc = u32::MAX;
        for byte in data {
            crc ^= u32::from(*byte);
            for _ in 0..8 {
                let mask = (crc & 1).wrapping_neg();
                crc = (crc >> 1) ^ (POLYNOMIAL & mask);
            }
        }
        !crc
    }

    #[test]
    fn check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        assert_eq!(crc32(b"a"), 0xE8B7_BE43);
        assert_eq!(
            crc32(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
    }

    #[test]
    fn incremental_and_table_match_bitwise() {
        let data: [u8; 300] = core::array::from_fn(|i| (i * 37 + 11) as u8);
        let mut crc = Crc32::new();
        for chunk in data.chunks(7) {
            crc.update(chunk);
        }
        assert_eq!(crc.finish(), crc32(&data));
        for len in [0, 1, 2, 3, 31, 64, 255, 300] {
            assert_eq!(
                crc32(&data[..len]),
                crc32_bitwise(&data[..len]),
                "len {len}"
            );
        }
    }
}
