//! "Calibrate this catheter from labelled pairs": one stiffness scale fitted to the pairs the
//! page holds whose force label was measured (or typed, imported, simulated; never one copied
//! from a model's estimate, which would fit the model to itself), each pair's physics estimate
//! read as the 3D step reads it. The rule is `hnet calibrate`'s
//! ([`hnet_twin::reconstruction::catalogue::calibrate_stiffness`]): too few pairs, unloaded pairs or pairs one
//! stiffness cannot explain are refused, saying why. The scale then multiplies the stiffness the
//! page assumes ([`crate::catheter_3d::PairGeometry::of`]).

use hnet_twin::reconstruction::catalogue::{
    BENCH_CATHETER, CalibrationError, StiffnessCalibration, calibrate_stiffness, catalogue,
};

use crate::catheter_3d::{FitMasks, PairGeometry, PairMasks, reconstruct_pair};
use crate::twin_live::TwinControls;
use crate::workspace::LabeledPair;
use hnet_units::with_causes;

/// A calibration and the pairs it could not use.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationOutcome {
    /// The fitted scale, its standard error and how much of the forces it explains.
    pub calibration: StiffnessCalibration,
    /// Each pair left out, and why.
    pub left_out: Vec<String>,
}

/// Why no calibration came out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CatheterCalibrationError {
    /// No pair carries a force label that is not a model's estimate.
    #[error(
        "no pair has a measured force label to calibrate on{}",
        if *.estimates > 0 { " (labels copied from H-Net's estimate are not measurements)" } else { "" }
    )]
    NoLabels {
        /// Pairs whose label is a model's estimate.
        estimates: usize,
    },
    /// The labelled pairs do not determine one stiffness.
    #[error("cannot calibrate the catheter from {pairs} labelled pair(s)")]
    Refused {
        /// Pairs tried.
        pairs: usize,
        /// Why.
        #[source]
        why: CalibrationError,
    },
}

/// Fits the stiffness scale to `pairs`' force labels. Each pair's catheter is read from its label
/// masks, else H-Net's (`predicted`: its masks of views A and B by pair id), with the geometry the
/// page reads it with (`controls`: the twin tab's catheter, for uploads and DICOM frames).
pub fn calibrate_catheter(
    pairs: &[LabeledPair],
    predicted: &dyn Fn(&str) -> Option<[Vec<f32>; 2]>,
    controls: &TwinControls,
) -> Result<CalibrationOutcome, CatheterCalibrationError> {
    let labelled: Vec<&LabeledPair> = pairs
        .iter()
        .filter(|p| p.force_n.is_some() && !p.force_origin.is_estimate())
        .collect();
    if labelled.is_empty() {
        let estimates = pairs
            .iter()
            .filter(|p| p.force_origin.is_estimate())
            .count();
        return Err(CatheterCalibrationError::NoLabels { estimates });
    }
    let mut left_out = Vec::new();
    let mut forces = Vec::new();
    for pair in &labelled {
        let masks = predicted(&pair.id);
        let read = PairMasks::of(
            pair,
            masks.as_ref().map(|[a, b]| [&a[..], &b[..]]),
            FitMasks::LabelsFirst,
        )
        .and_then(|masks| reconstruct_pair(&PairGeometry::of(pair, controls, None)?, &masks));
        match (read, pair.force_n) {
            (Ok(catheter), Some(label)) => forces.push((label, catheter.force_n)),
            (Err(e), _) => left_out.push(format!("{}: {}", pair.id, with_causes(&e))),
            (Ok(_), None) => {}
        }
    }
    let nominal = catalogue()
        .into_iter()
        .find(|c| c.name == BENCH_CATHETER)
        .expect("the bench catheter is in the catalogue");
    let calibrated = calibrate_stiffness(&nominal, &forces).map_err(|why| {
        CatheterCalibrationError::Refused {
            pairs: labelled.len(),
            why,
        }
    })?;
    Ok(CalibrationOutcome {
        calibration: calibrated
            .calibration
            .expect("a calibrated catheter records its calibration"),
        left_out,
    })
}

/// The calibration in words, for the model bar and the notice.
pub fn describe(calibration: &StiffnessCalibration) -> String {
    format!(
        "stiffness ×{:.2} ± {:.2} of what the page assumes, from {} labelled pairs ({:.0} % of \
         their forces explained)",
        calibration.scale,
        calibration.scale_sd,
        calibration.pairs,
        calibration.explained * 100.0
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin_live::XrayBackground;
    use hnet_twin::dataset::label_origin::LabelOrigin;
    use hnet_units::TipForce;

    /// Twin pairs of a catheter 30 % stiffer than the catalogue's, labelled with their true
    /// force: the scale comes out near 1.3, and a model's estimate as a label is never used.
    #[test]
    fn a_stiffer_catheter_is_found_from_its_labelled_twin_pairs() {
        let background = XrayBackground::phantom();
        let stiffer = TwinControls {
            stiffness_mn_m2: 0.78,
            ..TwinControls::default()
        };
        let mut pairs: Vec<LabeledPair> = [
            [0.15, 0.05, -0.10],
            [-0.1, 0.12, -0.08],
            [0.05, -0.15, -0.12],
        ]
        .into_iter()
        .enumerate()
        .map(|(i, force_n)| {
            let mut pair = TwinControls {
                force_n: TipForce::from_newtons(force_n),
                ..stiffer
            }
            .render(format!("t{i}"), &background)
            .unwrap();
            pair.force_n = pair.true_force();
            pair.force_origin = LabelOrigin::Simulated;
            pair
        })
        .collect();
        let none = |_: &str| None;
        let outcome = calibrate_catheter(&pairs, &none, &TwinControls::default()).unwrap();
        let scale = outcome.calibration.scale;
        assert!((scale - 1.3).abs() < 0.1, "{outcome:?}");
        assert!(describe(&outcome.calibration).starts_with("stiffness ×1."));
        // Two pairs are too few; said so.
        let error = calibrate_catheter(&pairs[..2], &none, &TwinControls::default()).unwrap_err();
        assert!(
            with_causes(&error).contains("at least 3 are needed"),
            "{error}"
        );
        // Labels copied from H-Net's estimate are no measurement.
        for pair in &mut pairs {
            pair.force_origin = LabelOrigin::Estimate {
                weights: "hnet-cpu.bpk".into(),
                estimator: "H-Net".into(),
            };
        }
        let error = calibrate_catheter(&pairs, &none, &TwinControls::default()).unwrap_err();
        assert_eq!(error, CatheterCalibrationError::NoLabels { estimates: 3 });
        assert!(error.to_string().contains("not measurements"));
    }
}
