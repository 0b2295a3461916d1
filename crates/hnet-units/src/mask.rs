//! Which pixels of a catheter mask are catheter: the one threshold of the network's metrics, the
//! twin's reconstruction, the CLI's mask files and the page.
//!
//! A mask is held either as catheter probabilities (a network's output, or a label read as
//! `value / 255`), 0-1, or as 8-bit labels (the dataset's mask PNGs, the twin's coverage, the
//! page's painted masks: 0 background, 255 catheter, anti-aliased values between). Both are cut
//! at one half: [`is_catheter`] and [`is_catheter_label`] agree on every 8-bit value read as a
//! probability.

use serde::{Deserialize, Serialize};

/// Catheter probability at or above which a pixel counts as catheter, 0-1 (in predictions and in
/// targets alike).
pub const MASK_THRESHOLD: f32 = 0.5;

/// The 8-bit label value at or above which a pixel counts as catheter: the smallest `v` with
/// `v / 255 >= MASK_THRESHOLD` (127/255 = 0.498, 128/255 = 0.502).
pub const LABEL_THRESHOLD: u8 = 128;

/// A catheter pixel's 8-bit label (a background pixel's is 0).
pub const CATHETER_LABEL: u8 = 255;

/// Whether catheter probability `p` (0-1) calls its pixel catheter (NaN does not).
pub fn is_catheter(p: f32) -> bool {
    p >= MASK_THRESHOLD
}

/// Whether 8-bit label `v` (0-255) calls its pixel catheter.
pub fn is_catheter_label(v: u8) -> bool {
    v >= LABEL_THRESHOLD
}

/// How many ways a network reads each view before its mask is kept: the view as given, or also
/// its left-right mirror image, the two catheter probabilities averaged
/// (`hnet_model::mask_averaging`). A weights file's recorded calibration says which it was
/// measured with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaskAveraging {
    /// One reading: the view as given.
    #[default]
    Single,
    /// The view and its left-right mirror image: two readings, twice the network's work.
    Mirrored,
}

impl MaskAveraging {
    /// Every setting, in order of cost.
    pub const ALL: [Self; 2] = [Self::Single, Self::Mirrored];

    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Single => "single",
            Self::Mirrored => "mirrored",
        }
    }

    /// The setting of a [`Self::name`]; an error that names the settings for any other text.
    pub fn from_name(name: &str) -> Result<Self, UnknownMaskAveraging> {
        Self::ALL
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| UnknownMaskAveraging(name.to_string()))
    }

    /// Readings of each view.
    pub fn readings(self) -> usize {
        match self {
            Self::Single => 1,
            Self::Mirrored => 2,
        }
    }

    /// Whether one reading (the default, which files leave out).
    pub fn is_single(&self) -> bool {
        *self == Self::Single
    }
}

/// A name that is no [`MaskAveraging`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownMaskAveraging(pub String);

impl core::fmt::Display for UnknownMaskAveraging {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "no way of reading a view is called `{}` (single or mirrored)",
            self.0
        )
    }
}

impl core::error::Error for UnknownMaskAveraging {}

/// The 8-bit label of a pixel: [`CATHETER_LABEL`] for catheter, 0 for background.
pub fn label(catheter: bool) -> u8 {
    if catheter { CATHETER_LABEL } else { 0 }
}

/// The binary 8-bit labels (0 or 255) of catheter probabilities, cut at [`MASK_THRESHOLD`].
pub fn binarize(probabilities: &[f32]) -> Vec<u8> {
    probabilities
        .iter()
        .map(|&p| label(is_catheter(p)))
        .collect()
}

/// The binary 8-bit labels (0 or 255) of 8-bit coverage (anti-aliased labels), cut at
/// [`LABEL_THRESHOLD`].
pub fn binarize_labels(coverage: &[u8]) -> Vec<u8> {
    coverage
        .iter()
        .map(|&v| label(is_catheter_label(v)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_averagings_read_back_by_name_and_others_are_named() {
        for averaging in MaskAveraging::ALL {
            assert_eq!(MaskAveraging::from_name(averaging.name()), Ok(averaging));
        }
        let err = MaskAveraging::from_name("twice").unwrap_err();
        assert_eq!(
            err.to_string(),
            "no way of reading a view is called `twice` (single or mirrored)"
        );
    }

    #[test]
    fn labels_and_probabilities_are_cut_at_the_same_half() {
        for v in 0..=255u8 {
            assert_eq!(
                is_catheter_label(v),
                is_catheter(f32::from(v) / 255.0),
                "label {v}"
            );
        }
        assert!(is_catheter(MASK_THRESHOLD) && !is_catheter(0.499_999) && !is_catheter(f32::NAN));
        assert_eq!(binarize(&[0.2, 0.5, 0.9, f32::NAN]), vec![0, 255, 255, 0]);
        assert_eq!(binarize_labels(&[0, 127, 128, 255]), vec![0, 0, 255, 255]);
    }
}
