//! A cine's frames as stored (8-16-bit monochrome values, kept compactly as 16-bit codes), the
//! modality LUT (Rescale Slope/Intercept) and their conversion to 8-bit grey through a window.

use hnet_units::ImageSize;

use crate::window::WindowLevel;

/// How stored values are kept: as 16-bit codes, signed values shifted up by half their range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelCoding {
    /// Bits Stored (1-16).
    pub bits_stored: u16,
    /// Pixel Representation 1: two's complement values.
    pub signed: bool,
}

impl PixelCoding {
    /// The code of the lowest stored value is 0; this is the stored value of code 0.
    fn offset(self) -> i32 {
        if self.signed {
            -(1 << (self.bits_stored - 1))
        } else {
            0
        }
    }

    /// Number of distinct codes, `2^bits_stored`.
    pub fn codes(self) -> usize {
        1 << self.bits_stored
    }

    /// The code of a raw sample as found in the pixel data (bits above Bits Stored ignored,
    /// the sign taken from the highest stored bit).
    pub fn code_of_raw(self, raw: u16) -> u16 {
        let mask = (self.codes() - 1) as u16;
        let value = raw & mask;
        if self.signed {
            // Shifting by half the range turns two's complement into offset binary.
            value ^ (1 << (self.bits_stored - 1))
        } else {
            value
        }
    }

    /// The stored value of a code.
    pub fn stored_value(self, code: u16) -> i32 {
        i32::from(code) + self.offset()
    }
}

/// The modality LUT of X-ray frames: `value = slope · stored + intercept`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalityLut {
    /// Rescale Slope (1 when absent).
    pub slope: f64,
    /// Rescale Intercept (0 when absent).
    pub intercept: f64,
}

impl Default for ModalityLut {
    fn default() -> Self {
        Self {
            slope: 1.0,
            intercept: 0.0,
        }
    }
}

impl ModalityLut {
    /// The modality value of a stored value.
    pub fn apply(&self, stored: i32) -> f64 {
        self.slope * f64::from(stored) + self.intercept
    }
}

/// MONOCHROME1 shows low values white (inverted after the window), MONOCHROME2 black.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Monochrome {
    /// Minimum value is white.
    One,
    /// Minimum value is black.
    Two,
}

/// The frames of one plane: `count` frames of `size` pixels, row-major, as codes.
#[derive(Debug, Clone, PartialEq)]
pub struct Frames {
    /// Image size, pixels.
    pub size: ImageSize,
    /// How the codes map to stored values.
    pub coding: PixelCoding,
    /// Stored to modality values.
    pub modality: ModalityLut,
    /// MONOCHROME1 or MONOCHROME2.
    pub monochrome: Monochrome,
    /// Every frame's codes, one frame after the other.
    pub codes: Vec<u16>,
}

impl Frames {
    /// Number of frames.
    pub fn count(&self) -> usize {
        self.codes.len() / self.size.pixels().max(1)
    }

    /// Frame `index`'s codes (0-based), `None` past the last frame.
    pub fn frame(&self, index: usize) -> Option<&[u16]> {
        let pixels = self.size.pixels();
        self.codes.get(index * pixels..(index + 1) * pixels)
    }

    /// The modality value of a code.
    pub fn value(&self, code: u16) -> f64 {
        self.modality.apply(self.coding.stored_value(code))
    }

    /// The lowest and highest modality values of frame `index`.
    pub fn range(&self, index: usize) -> Option<(f64, f64)> {
        let frame = self.frame(index)?;
        let (lo, hi) = frame
            .iter()
            .fold((u16::MAX, 0), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        if frame.is_empty() {
            return None;
        }
        let (a, b) = (self.value(lo), self.value(hi));
        Some((a.min(b), a.max(b)))
    }

    /// The 8-bit grey of each code under `window` (inverted for MONOCHROME1): a table that the
    /// cine player can reuse for every frame while the window stays put.
    pub fn grey_table(&self, window: WindowLevel) -> Vec<u8> {
        (0..self.coding.codes())
            .map(|code| {
                let grey = window.grey(self.value(code as u16));
                match self.monochrome {
                    Monochrome::One => 255 - grey,
                    Monochrome::Two => grey,
                }
            })
            .collect()
    }

    /// Frame `index` as 8-bit grey under `window`, row-major.
    pub fn grey_frame(&self, index: usize, window: WindowLevel) -> Option<Vec<u8>> {
        let table = self.grey_table(window);
        Some(
            self.frame(index)?
                .iter()
                .map(|&c| table[usize::from(c)])
                .collect(),
        )
    }

    /// Every frame, one after the other, as one series (the frames of a plane split over files).
    /// `None` when the frames differ in size or coding.
    pub fn concatenated(parts: Vec<Frames>) -> Option<Frames> {
        let mut parts = parts.into_iter();
        let mut all = parts.next()?;
        for part in parts {
            if (part.size, part.coding, part.monochrome) != (all.size, all.coding, all.monochrome) {
                return None;
            }
            all.codes.extend(part.codes);
        }
        Some(all)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_values_keep_their_order_as_codes() {
        let coding = PixelCoding {
            bits_stored: 12,
            signed: true,
        };
        // -2048, -1, 0, 2047 in 12-bit two's complement (high bits set as scanners do).
        let raw = [0x0800u16, 0xFFFF, 0x0000, 0x07FF];
        let codes: Vec<u16> = raw.iter().map(|&r| coding.code_of_raw(r)).collect();
        assert!(codes.windows(2).all(|w| w[0] < w[1]), "{codes:?}");
        let values: Vec<i32> = codes.iter().map(|&c| coding.stored_value(c)).collect();
        assert_eq!(values, [-2048, -1, 0, 2047]);
    }

    #[test]
    fn monochrome1_is_inverted_after_the_window() {
        let frames = |monochrome| Frames {
            size: ImageSize::new(2, 1),
            coding: PixelCoding {
                bits_stored: 8,
                signed: false,
            },
            modality: ModalityLut {
                slope: 2.0,
                intercept: -10.0,
            },
            monochrome,
            codes: vec![5, 105],
        };
        let two = frames(Monochrome::Two);
        assert_eq!(two.range(0), Some((0.0, 200.0)));
        let window = WindowLevel::spanning(0.0, 200.0);
        assert_eq!(two.grey_frame(0, window), Some(vec![0, 255]));
        assert_eq!(
            frames(Monochrome::One).grey_frame(0, window),
            Some(vec![255, 0])
        );
    }
}
