//! The catheter in 3D from its two masks, and the tip force of the rod that fits it (a
//! physics-checked force, no training).
//!
//! - [`centreline`]: each view's sub-pixel centreline (and whether a view shows a catheter);
//! - [`epipolar`]: epipolar matching of the two centrelines and triangulation;
//! - [`rod_fit`]: the twin's rod fitted to the 3D curve, the force its fit implies;
//! - [`physics_force`]: the three on a pair's masks in one call, with the oracle or the blind
//!   setup;
//! - [`catalogue`]: the named catheters a blind estimate assumes, and their calibration from
//!   pairs with a measured force.

pub mod catalogue;
pub mod centreline;
pub mod epipolar;
pub mod physics_force;
pub mod rod_fit;

use serde::{Deserialize, Serialize};

/// Which masks a catheter was reconstructed from: the one name of the page's 3D reading and the
/// CLI's physics check.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskOrigin {
    /// The pair's label masks (the dataset's; exact for simulated pairs). Spelled `true` in
    /// files, as the CLI's results have always said it.
    #[serde(rename = "true")]
    Labels,
    /// A network's predicted masks (probabilities).
    Predicted,
}

impl MaskOrigin {
    /// In a sentence: `the label masks` or `H-Net's masks` (the page's words).
    pub fn phrase(self) -> &'static str {
        match self {
            Self::Labels => "the label masks",
            Self::Predicted => "H-Net's masks",
        }
    }

    /// As a table row names it: `true masks` or `predicted masks` (the CLI's reports).
    pub fn row_name(self) -> &'static str {
        match self {
            Self::Labels => "true masks",
            Self::Predicted => "predicted masks",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::MaskOrigin;

    #[test]
    fn mask_origins_keep_the_spelling_of_existing_result_files() {
        for (origin, json) in [
            (MaskOrigin::Labels, "\"true\""),
            (MaskOrigin::Predicted, "\"predicted\""),
        ] {
            assert_eq!(serde_json::to_string(&origin).unwrap(), json);
            assert_eq!(serde_json::from_str::<MaskOrigin>(json).unwrap(), origin);
        }
    }
}
