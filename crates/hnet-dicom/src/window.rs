//! The VOI LUT as viewers apply it: a window (centre and width, in modality units) mapped to 8-bit
//! grey with DICOM's linear function (PS3.3 C.11.2.1.2.1). A [`WindowLevel`] is a plain value;
//! dragging on the page makes a new one, and applying it is a pure function.

/// A window: grey 0 up to `centre - width/2`, grey 255 from `centre + width/2`, linear between.
/// Both in modality units (stored values after Rescale Slope/Intercept).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowLevel {
    /// Window Center.
    pub centre: f64,
    /// Window Width, at least 1.
    pub width: f64,
}

impl WindowLevel {
    /// A window of `width` (at least 1) about `centre`.
    pub fn new(centre: f64, width: f64) -> Self {
        Self {
            centre,
            width: width.max(1.0),
        }
    }

    /// The window that maps `min` to grey 0 and `max` to grey 255 (used when the header has no
    /// Window Center/Width: the frame's range).
    pub fn spanning(min: f64, max: f64) -> Self {
        let (min, max) = (min.min(max), max.max(min));
        Self::new((min + max) / 2.0 + 0.5, max - min + 1.0)
    }

    /// This window moved by `d_centre` and widened by `d_width` (modality units), as a drag on an
    /// image does (horizontal: width, vertical: centre, by convention of the caller).
    pub fn dragged(self, d_centre: f64, d_width: f64) -> Self {
        Self::new(self.centre + d_centre, self.width + d_width)
    }

    /// The 8-bit grey of a modality value.
    pub fn grey(&self, value: f64) -> u8 {
        let lower = self.centre - 0.5 - (self.width - 1.0) / 2.0;
        let upper = self.centre - 0.5 + (self.width - 1.0) / 2.0;
        if value <= lower {
            0
        } else if value > upper {
            255
        } else {
            (((value - (self.centre - 0.5)) / (self.width - 1.0) + 0.5) * 255.0)
                .round()
                .clamp(0.0, 255.0) as u8
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_linear_function_spans_the_window() {
        let window = WindowLevel::new(100.0, 201.0);
        assert_eq!(window.grey(-1.0), 0);
        assert_eq!(window.grey(-0.5), 0);
        assert_eq!(window.grey(99.5), 128);
        assert_eq!(window.grey(200.0), 255);
        assert_eq!(window.grey(1e6), 255);
        let range = WindowLevel::spanning(-50.0, 450.0);
        assert_eq!((range.grey(-50.0), range.grey(450.0)), (0, 255));
        assert_eq!(WindowLevel::spanning(7.0, 7.0).grey(7.0), 0);
        assert_eq!(window.dragged(10.0, -1000.0), WindowLevel::new(110.0, 1.0));
    }
}
