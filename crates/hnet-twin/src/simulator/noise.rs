//! Fast, reproducible noise for the renderers: xoshiro256+ seeded from the sample's generator.
//!
//! Image noise needs hundreds of thousands of normal deviates per sample; drawing them from the
//! cryptographic-quality ChaCha stream would dominate the render time.

use rand::Rng;

/// A xoshiro256+ generator of noise values.
#[derive(Debug, Clone)]
pub struct Noise {
    state: [u64; 4],
}

impl Noise {
    /// A generator seeded from `rng` (advancing it by four words).
    pub fn from_rng(rng: &mut impl Rng) -> Self {
        let mut state = [0u64; 4];
        for s in &mut state {
            *s = rng.next_u64();
        }
        if state == [0; 4] {
            state[0] = 1;
        }
        Self { state }
    }

    fn next(&mut self) -> u64 {
        let s = &mut self.state;
        let result = s[0].wrapping_add(s[3]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// A standard normal deviate, approximated by the sum of four uniforms (Irwin-Hall): fast,
    /// exact in mean and variance, bounded at ±3.5 σ, plenty for image noise.
    pub fn normal(&mut self) -> f32 {
        let bits = self.next();
        let sum =
            (bits & 0xFFFF) + ((bits >> 16) & 0xFFFF) + ((bits >> 32) & 0xFFFF) + (bits >> 48);
        // Four uniforms on [0, 1) have mean 2 and variance 1/3.
        ((sum as f32 / 65536.0) - 2.0) * 1.732_050_8
    }

    /// A uniform value in `[0, 1)`.
    pub fn uniform(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn normals_have_zero_mean_and_unit_variance() {
        let mut noise = Noise::from_rng(&mut rand_chacha::ChaCha8Rng::seed_from_u64(5));
        let n = 200_000;
        let values: Vec<f64> = (0..n).map(|_| f64::from(noise.normal())).collect();
        let mean = values.iter().sum::<f64>() / n as f64;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.01, "{var}");
        let u: f32 = (0..1000).map(|_| noise.uniform()).fold(0.0, f32::max);
        assert!(u < 1.0 && u > 0.99);
    }
}
