//! A small seeded PRNG for host-side training: parameter initialization, batch sampling and
//! diffusion noise. Candle's own RNG cannot be seeded on the CPU, so every random number used by
//! training and float sampling comes from here (xoshiro256** seeded through frmd-core's
//! SplitMix64, Gaussian samples by [`box_muller`], which the task streams share).

use frmd_core::rng::SplitMix64;

/// Deterministic generator: the same seed gives the same stream on every machine.
#[derive(Clone, Debug)]
pub struct HostRng {
    state: [u64; 4],
    spare_normal: Option<f64>,
}

/// Two independent standard normal samples from `u1` in (0, 1] and `u2` in [0, 1) (the
/// Box-Muller transform): `r cos(2 pi u2)` and `r sin(2 pi u2)` with `r = sqrt(-2 ln u1)`.
pub fn box_muller(u1: f64, u2: f64) -> (f64, f64) {
    let radius = (-2.0 * u1.ln()).sqrt();
    let angle = std::f64::consts::TAU * u2;
    (radius * angle.cos(), radius * angle.sin())
}

impl HostRng {
    /// The stream of `seed`.
    pub fn new(seed: u64) -> Self {
        let mut seeder = SplitMix64::new(seed);
        let state = std::array::from_fn(|_| seeder.next_u64());
        HostRng {
            state,
            spare_normal: None,
        }
    }

    /// An independent stream derived from this seed and a label (e.g. one per purpose).
    pub fn derive(seed: u64, label: &str) -> Self {
        let mut h = seed ^ 0xA076_1D64_78BD_642F;
        for byte in label.bytes() {
            h = (h ^ u64::from(byte)).wrapping_mul(0x100_0000_01B3);
        }
        HostRng::new(h)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.state;
        let result = s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in 0..n (n > 0; returns 0 for n == 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            return 0;
        }
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }

    /// Standard normal sample.
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let (z, spare) = box_muller(u1, self.uniform());
        self.spare_normal = Some(spare);
        z
    }

    /// `len` standard normal samples as f32.
    pub fn normal_vec(&mut self, len: usize) -> Vec<f32> {
        (0..len).map(|_| self.normal() as f32).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproducible_and_roughly_standard() {
        let mut a = HostRng::new(7);
        let mut b = HostRng::new(7);
        assert_eq!(a.next_u64(), b.next_u64());
        let xs: Vec<f64> = (0..20000).map(|_| a.normal()).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.05,
            "mean {mean} var {var}"
        );
        assert_ne!(
            HostRng::derive(1, "a").next_u64(),
            HostRng::derive(1, "b").next_u64()
        );
    }

    /// The stream every checkpoint and recorded result was made with, to the bit.
    #[test]
    fn recorded_stream_is_unchanged() {
        let mut rng = HostRng::new(7);
        let bits: Vec<u64> = (0..3).map(|_| rng.next_u64()).collect();
        assert_eq!(
            bits,
            [0xb358faf74ef9765a, 0x475c3d964f482cd2, 0xd6f1d349952c7996]
        );
        let normals: Vec<u64> = (0..3).map(|_| rng.normal().to_bits()).collect();
        assert_eq!(
            normals,
            [0x4006803c052962a1, 0xbfc4b2791c2b5a85, 0x3ffe26f011359475]
        );
        assert_eq!(HostRng::derive(3, "noise").next_u64(), 0x63079ed36c1d4ae4);
    }
}
