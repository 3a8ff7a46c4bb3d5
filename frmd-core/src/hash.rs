//! FNV-1a (64-bit): a tiny, fixed, non-cryptographic hash for fingerprints that two machines must
//! agree on (the firmware's output digests, which the host recomputes; the dataset digest in a
//! checkpoint). `offset basis 0xcbf29ce484222325`, `prime 0x100000001b3`, per byte
//! `h = (h ^ byte) * prime` (wrapping).

const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
const PRIME: u64 = 0x0000_0100_0000_01b3;

/// Running FNV-1a 64 state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a64 {
    state: u64,
}

impl Fnv1a64 {
    /// The empty hash (the offset basis).
    pub const fn new() -> Self {
        Self {
            state: OFFSET_BASIS,
        }
    }

    /// Feeds `bytes` in order.
    pub fn bytes(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            self.state = (self.state ^ u64::from(byte)).wrapping_mul(PRIME);
        }
    }

    /// Feeds each value as its 4 little-endian IEEE-754 bytes, in slice order.
    pub fn f32s(&mut self, values: &[f32]) {
        for value in values {
            self.bytes(&value.to_le_bytes());
        }
    }

    /// The hash of everything fed so far.
    pub fn finish(&self) -> u64 {
        self.state
    }

    /// The hash of `bytes` alone.
    pub fn of(bytes: &[u8]) -> u64 {
        let mut hash = Self::new();
        hash.bytes(bytes);
        hash.finish()
    }
}

impl Default for Fnv1a64 {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::Fnv1a64;

    #[test]
    fn matches_published_vectors() {
        assert_eq!(Fnv1a64::of(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(Fnv1a64::of(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(Fnv1a64::of(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn floats_hash_as_little_endian_bytes() {
        let mut by_value = Fnv1a64::new();
        by_value.f32s(&[1.0, -2.5]);
        let mut bytes = [0_u8; 8];
        bytes[..4].copy_from_slice(&1.0_f32.to_le_bytes());
        bytes[4..].copy_from_slice(&(-2.5_f32).to_le_bytes());
        assert_eq!(by_value.finish(), Fnv1a64::of(&bytes));
    }
}
