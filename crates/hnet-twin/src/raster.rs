//! Floating-point images (values in `[0, 1]`, row-major) and the few operations the renderers
//! need: bilinear resampling, Gaussian blur and conversion to 8 bits.

use serde::{Deserialize, Serialize};

/// Normalised rectangle inside an image: `[x0, y0, x1, y1]` with 0 at the left/top edge and 1 at
/// the right/bottom edge.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rect(pub [f64; 4]);

impl Rect {
    /// A rectangle from its centre and size, both normalised.
    pub fn centred(centre: [f64; 2], size: [f64; 2]) -> Self {
        Self([
            centre[0] - size[0] / 2.0,
            centre[1] - size[1] / 2.0,
            centre[0] + size[0] / 2.0,
            centre[1] + size[1] / 2.0,
        ])
    }

    /// The rectangle moved and shrunk as needed to fit inside the unit square.
    pub fn clamped(self) -> Self {
        let [x0, y0, x1, y1] = self.0;
        let w = (x1 - x0).clamp(1e-3, 1.0);
        let h = (y1 - y0).clamp(1e-3, 1.0);
        let x0 = x0.clamp(0.0, 1.0 - w);
        let y0 = y0.clamp(0.0, 1.0 - h);
        Self([x0, y0, x0 + w, y0 + h])
    }
}

/// A grey image with values in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct GreyImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width·height` values, row-major.
    pub data: Vec<f32>,
}

impl GreyImage {
    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// An image from 8-bit grey pixels.
    pub fn from_u8(width: usize, height: usize, pixels: &[u8]) -> Self {
        Self {
            width,
            height,
            data: pixels.iter().map(|&v| f32::from(v) / 255.0).collect(),
        }
    }

    /// 8-bit grey pixels (values clamped to `[0, 1]`, rounded).
    pub fn to_u8(&self) -> Vec<u8> {
        self.data.iter().map(|&v| to_byte(v)).collect()
    }

    /// The value at pixel coordinates `(x, y)` (continuous, pixel centres at `i + 0.5`), with
    /// bilinear interpolation and clamping at the borders.
    pub fn sample(&self, x: f64, y: f64) -> f32 {
        let fx = (x - 0.5).clamp(0.0, (self.width - 1) as f64);
        let fy = (y - 0.5).clamp(0.0, (self.height - 1) as f64);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
        let at = |x: usize, y: usize| self.data[y * self.width + x];
        let top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
        let bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
        top * (1.0 - ty) + bottom * ty
    }

    /// The part of the image inside `rect`, resampled to `width` x `height`. Downscaling
    /// averages the source over each output pixel (box filter) so that it does not alias.
    pub fn crop_resampled(&self, rect: Rect, width: usize, height: usize) -> GreyImage {
        let [x0, y0, x1, y1] = rect.0;
        let sx = (x1 - x0) * self.width as f64 / width as f64;
        let sy = (y1 - y0) * self.height as f64 / height as f64;
        // Sub-samples per output pixel along each axis when shrinking.
        let nx = sx.ceil().max(1.0) as usize;
        let ny = sy.ceil().max(1.0) as usize;
        let mut data = Vec::with_capacity(width * height);
        for j in 0..height {
            for i in 0..width {
                let mut sum = 0.0;
                for b in 0..ny {
                    for a in 0..nx {
                        let x =
                            x0 * self.width as f64 + (i as f64 + (a as f64 + 0.5) / nx as f64) * sx;
                        let y = y0 * self.height as f64
                            + (j as f64 + (b as f64 + 0.5) / ny as f64) * sy;
                        sum += self.sample(x, y);
                    }
                }
                data.push(sum / (nx * ny) as f32);
            }
        }
        GreyImage {
            width,
            height,
            data,
        }
    }

    /// Separable Gaussian blur with standard deviation `sigma_px` (no-op for `sigma_px <= 0`).
    pub fn blurred(&self, sigma_px: f64) -> GreyImage {
        let kernel = gaussian_kernel(sigma_px);
        if kernel.len() == 1 {
            return self.clone();
        }
        let horizontal = convolve(&self.data, self.width, self.height, 1, &kernel, true);
        GreyImage {
            width: self.width,
            height: self.height,
            data: convolve(&horizontal, self.width, self.height, 1, &kernel, false),
        }
    }

    /// Mean value.
    pub fn mean(&self) -> f32 {
        self.data.iter().sum::<f32>() / self.data.len().max(1) as f32
    }
}

/// An RGB image with values in `[0, 1]`, three values per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `3·width·height` values, row-major, RGB interleaved.
    pub data: Vec<f32>,
}

impl RgbImage {
    /// 8-bit RGB pixels.
    pub fn to_u8(&self) -> Vec<u8> {
        self.data.iter().map(|&v| to_byte(v)).collect()
    }

    /// Separable Gaussian blur of every channel.
    pub fn blurred(&self, sigma_px: f64) -> RgbImage {
        let kernel = gaussian_kernel(sigma_px);
        if kernel.len() == 1 {
            return self.clone();
        }
        let horizontal = convolve(&self.data, self.width, self.height, 3, &kernel, true);
        RgbImage {
            width: self.width,
            height: self.height,
            data: convolve(&horizontal, self.width, self.height, 3, &kernel, false),
        }
    }
}

/// `[0, 1]` to a byte, rounding to nearest.
pub fn to_byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let radius = (3.0 * sigma).ceil() as i64;
    let weights: Vec<f64> = (-radius..=radius)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = weights.iter().sum();
    weights.iter().map(|w| (w / sum) as f32).collect()
}

/// One pass of a 1D convolution along rows (`horizontal`) or columns, clamping at the borders.
fn convolve(
    data: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    kernel: &[f32],
    horizontal: bool,
) -> Vec<f32> {
    let radius = (kernel.len() / 2) as isize;
    let mut out = vec![0.0; data.len()];
    for y in 0..height {
        for x in 0..width {
            for c in 0..channels {
                let mut acc = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let offset = k as isize - radius;
                    let (sx, sy) = if horizontal {
                        (
                            (x as isize + offset).clamp(0, width as isize - 1) as usize,
                            y,
                        )
                    } else {
                        (
                            x,
                            (y as isize + offset).clamp(0, height as isize - 1) as usize,
                        )
                    };
                    acc += w * data[(sy * width + sx) * channels + c];
                }
                out[(y * width + x) * channels + c] = acc;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blur_preserves_the_mean_of_a_flat_image_and_spreads_a_point() {
        let flat = GreyImage::filled(8, 8, 0.4);
        assert!(
            flat.blurred(1.0)
                .data
                .iter()
                .all(|v| (v - 0.4).abs() < 1e-6)
        );
        let mut point = GreyImage::filled(9, 9, 0.0);
        point.data[4 * 9 + 4] = 1.0;
        let b = point.blurred(1.0);
        assert!((b.data.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        assert!(b.data[4 * 9 + 4] < 0.2 && b.data[4 * 9 + 5] > 0.05);
    }

    #[test]
    fn cropping_the_whole_image_at_the_same_size_is_the_identity() {
        let img = GreyImage {
            width: 4,
            height: 3,
            data: (0..12).map(|v| v as f32 / 11.0).collect(),
        };
        let same = img.crop_resampled(Rect([0.0, 0.0, 1.0, 1.0]), 4, 3);
        for (a, b) in img.data.iter().zip(&same.data) {
            assert!((a - b).abs() < 1e-6);
        }
        // Halving averages 2x2 blocks.
        let half = img.crop_resampled(Rect([0.0, 0.0, 1.0, 1.0]), 2, 1);
        assert_eq!(half.data.len(), 2);
    }

    #[test]
    fn rects_are_clamped_into_the_image() {
        let r = Rect::centred([0.95, 0.5], [0.2, 0.4]).clamped();
        assert!((r.0[2] - 1.0).abs() < 1e-12 && (r.0[0] - 0.8).abs() < 1e-12);
    }
}
