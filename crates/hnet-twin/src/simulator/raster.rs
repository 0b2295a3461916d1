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
        // Bilinear taps `(low index, high index, weight of high)` of every sub-sample along
        // one axis, `n` sub-samples per output pixel when shrinking.
        let taps = |start: f64, extent: f64, source: usize, out: usize| {
            let step = extent * source as f64 / out as f64;
            let n = step.ceil().max(1.0) as usize;
            let mut taps = Vec::with_capacity(out * n);
            for i in 0..out {
                for a in 0..n {
                    let c = start * source as f64 + (i as f64 + (a as f64 + 0.5) / n as f64) * step;
                    let f = (c - 0.5).clamp(0.0, (source - 1) as f64);
                    let low = f.floor() as usize;
                    taps.push((low, (low + 1).min(source - 1), (f - low as f64) as f32));
                }
            }
            (taps, n)
        };
        let (xs, nx) = taps(x0, x1 - x0, self.width, width);
        let (ys, ny) = taps(y0, y1 - y0, self.height, height);
        let norm = 1.0 / (nx * ny) as f32;
        let mut data = vec![0.0f32; width * height];
        let mut row = vec![0.0f32; width];
        for j in 0..height {
            row.iter_mut().for_each(|v| *v = 0.0);
            for &(ylo, yhi, ty) in &ys[j * ny..(j + 1) * ny] {
                let (top, bottom) = (
                    &self.data[ylo * self.width..(ylo + 1) * self.width],
                    &self.data[yhi * self.width..(yhi + 1) * self.width],
                );
                for (i, acc) in row.iter_mut().enumerate() {
                    for &(xlo, xhi, tx) in &xs[i * nx..(i + 1) * nx] {
                        let t = top[xlo] + (top[xhi] - top[xlo]) * tx;
                        let b = bottom[xlo] + (bottom[xhi] - bottom[xlo]) * tx;
                        *acc += t + (b - t) * ty;
                    }
                }
            }
            for (out, v) in data[j * width..(j + 1) * width].iter_mut().zip(&row) {
                *out = v * norm;
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
        GreyImage {
            width: self.width,
            height: self.height,
            data: gaussian_blur(&self.data, self.width, self.height, 1, sigma_px),
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

    /// Blurs the pixels in `[min, max)` (`[x, y]` corners) in place, reading beyond the region's
    /// edges where the image continues.
    pub fn blur_region(&mut self, min: [usize; 2], max: [usize; 2], sigma_px: f64) {
        let kernel = gaussian_kernel(sigma_px);
        let r = kernel.len() / 2;
        // Work on the region plus the kernel's reach, then copy the region's interior back.
        let (ex0, ey0) = (min[0].saturating_sub(r), min[1].saturating_sub(r));
        let (ex1, ey1) = ((max[0] + r).min(self.width), (max[1] + r).min(self.height));
        let (w, h) = (ex1 - ex0, ey1 - ey0);
        let mut patch = Vec::with_capacity(w * h * 3);
        for y in ey0..ey1 {
            patch.extend_from_slice(
                &self.data[(y * self.width + ex0) * 3..(y * self.width + ex1) * 3],
            );
        }
        let blurred = RgbImage {
            width: w,
            height: h,
            data: patch,
        }
        .blurred(sigma_px);
        for y in min[1]..max[1] {
            let src = ((y - ey0) * w + (min[0] - ex0)) * 3;
            let dst = (y * self.width + min[0]) * 3;
            let n = (max[0] - min[0]) * 3;
            self.data[dst..dst + n].copy_from_slice(&blurred.data[src..src + n]);
        }
    }

    /// Separable Gaussian blur of every channel.
    pub fn blurred(&self, sigma_px: f64) -> RgbImage {
        RgbImage {
            width: self.width,
            height: self.height,
            data: gaussian_blur(&self.data, self.width, self.height, 3, sigma_px),
        }
    }
}

/// `data` (`channels` values per pixel, row-major) blurred by a separable Gaussian of standard
/// deviation `sigma_px` (a copy for `sigma_px <= 0`).
fn gaussian_blur(
    data: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    sigma_px: f64,
) -> Vec<f32> {
    let kernel = gaussian_kernel(sigma_px);
    if kernel.len() == 1 {
        return data.to_vec();
    }
    let horizontal = convolve(data, width, height, channels, &kernel, true);
    convolve(&horizontal, width, height, channels, &kernel, false)
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

/// One pass of a 1D convolution along rows (`horizontal`) or columns of each channel,
/// replicating the border pixels.
fn convolve(
    data: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    kernel: &[f32],
    horizontal: bool,
) -> Vec<f32> {
    let radius = kernel.len() / 2;
    let row = width * channels;
    let mut out = vec![0.0; data.len()];
    if horizontal {
        let mut padded = vec![0.0f32; width + 2 * radius];
        for y in 0..height {
            for c in 0..channels {
                let start = y * row + c;
                for (i, p) in padded.iter_mut().enumerate() {
                    let source = i.saturating_sub(radius).min(width - 1);
                    *p = data[start + source * channels];
                }
                for x in 0..width {
                    let window = &padded[x..x + kernel.len()];
                    out[start + x * channels] = window.iter().zip(kernel).map(|(v, k)| v * k).sum();
                }
            }
        }
    } else {
        // Whole rows at a time: memory is read in order and the inner loop vectorises. Each
        // pixel still sums its taps in kernel order, so the result is the same (up to the sign of
        // a zero sum).
        for (y, target) in out.chunks_exact_mut(row).enumerate() {
            for (k, &weight) in kernel.iter().enumerate() {
                let source = (y + k).saturating_sub(radius).min(height - 1);
                let line = &data[source * row..(source + 1) * row];
                for (t, v) in target.iter_mut().zip(line) {
                    *t += v * weight;
                }
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
    fn blurring_a_region_matches_blurring_everything_inside_it() {
        let mut image = RgbImage {
            width: 12,
            height: 10,
            data: (0..360).map(|v| ((v * 37) % 101) as f32 / 100.0).collect(),
        };
        let whole = image.blurred(0.8);
        image.blur_region([3, 2], [9, 7], 0.8);
        for y in 0..10 {
            for x in 0..12 {
                for c in 0..3 {
                    let i = (y * 12 + x) * 3 + c;
                    if (3..9).contains(&x) && (2..7).contains(&y) {
                        assert!((image.data[i] - whole.data[i]).abs() < 1e-6);
                    }
                }
            }
        }
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
