//! The sensor model: exposure gain, Gaussian read noise and 8-bit quantization, deterministic for
//! a seed (a counter-based hash per pixel and channel, so frames can be rendered in any order).

use image::RgbImage;

use crate::texture::mix64;

/// Turns lit colour into an 8-bit image: `round(255 · gain · rgb + noise)`, clamped.
pub fn expose(rgb: &[[f32; 3]], width: u32, height: u32, gain: f32, noise_sigma: f32, salt: u64) -> RgbImage {
    expose_channels(rgb, width, height, [gain; 3], noise_sigma, salt)
}

/// [`expose`] with a gain per channel (exposure times the light's colour).
pub fn expose_channels(
    rgb: &[[f32; 3]],
    width: u32,
    height: u32,
    gains: [f32; 3],
    noise_sigma: f32,
    salt: u64,
) -> RgbImage {
    let mut out = Vec::with_capacity(rgb.len() * 3);
    for (k, px) in rgb.iter().enumerate() {
        let h = mix64(salt ^ (k as u64).wrapping_mul(0x2545_f491_4f6c_dd1d));
        for (ch, &value) in px.iter().enumerate() {
            let noise =
                if noise_sigma > 0.0 { noise_sigma * standard_normal(mix64(h.wrapping_add(ch as u64))) } else { 0.0 };
            out.push((255.0 * gains[ch] * value + noise).round().clamp(0.0, 255.0) as u8);
        }
    }
    // The buffer has exactly width x height x 3 entries.
    RgbImage::from_raw(width, height, out).unwrap_or_else(|| RgbImage::new(width, height))
}

/// An approximately standard normal number from 64 random bits (Irwin–Hall sum of four 16-bit
/// uniforms, rescaled to unit variance; tails are cut at ±3.46σ, irrelevant for read noise).
pub fn standard_normal(bits: u64) -> f32 {
    let sum: u32 = (0..4).map(|i| ((bits >> (16 * i)) & 0xffff) as u32).sum();
    let u = sum as f32 / 65535.0; // sum of four U(0,1): mean 2, variance 1/3
    (u - 2.0) * 3f32.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_has_the_requested_spread_and_is_deterministic() {
        let rgb = vec![[0.5f32; 3]; 100 * 100];
        let a = expose(&rgb, 100, 100, 1.0, 2.0, 42);
        let b = expose(&rgb, 100, 100, 1.0, 2.0, 42);
        assert_eq!(a, b);
        let values: Vec<f64> = a.as_raw().iter().map(|&v| v as f64).collect();
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
        assert!((mean - 127.5).abs() < 0.1, "{mean}");
        // Rounding adds 1/12 of a level squared of variance: sqrt(4 + 1/12) = 2.02.
        assert!((sd - 2.02).abs() < 0.05, "{sd}");
    }
}
