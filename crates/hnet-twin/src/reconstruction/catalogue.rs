//! The catheters a blind force estimate may assume: a small catalogue of named catheters with
//! their nominal mechanics, and catheter files (`catheter.json`) that hold one such entry,
//! possibly calibrated from pairs labelled with a measured force ([`calibrate_stiffness`]).
//!
//! A blind estimate ([`crate::reconstruction::physics_force::PhysicsSetup::blind`]) never reads a pair's own
//! record: it assumes the catheter named here, and fits the base pose from a nominal one. The
//! entries are the twin's own catheters, named as a maker's data sheet would name them; they are
//! not measured data of commercial catheters.
//!
//! **Why the stiffness is calibrated and not fitted per pair.** Without gravity the rod's
//! equilibrium depends on the tip force and the bending stiffness only through `F/EI`
//! ([`crate::reconstruction::rod_fit`] refuses to fit both), so images alone cannot tell a stiff catheter under a
//! large force from a soft one under a small force. A few pairs with a measured force fix the
//! ratio: the force the images give under the nominal stiffness, scaled by `EI/EI_nominal`, is
//! the true force, so one scale fitted by least squares calibrates the catheter.

use hnet_units::TipForce;
use serde::{Deserialize, Serialize};

use crate::simulator::rod::RodConfig;

/// One catheter as a data sheet gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CatalogueCatheter {
    /// Its name in the catalogue, on the command line and in the page.
    pub name: String,
    /// What it is, in a sentence.
    pub description: String,
    /// Bending stiffness EI of the flexible section, N·m².
    pub bending_stiffness_n_m2: f64,
    /// Length of the flexible (deflectable) section, mm.
    pub flexible_length_mm: f64,
    /// Intrinsic curvature of the unloaded section (its pre-curve), 1/mm; 0 for a straight one.
    pub precurvature_per_mm: f64,
    /// Outer diameter, mm (7 Fr = 2.33 mm).
    pub diameter_mm: f64,
    /// How the stiffness was calibrated, when it was ([`calibrate_stiffness`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<StiffnessCalibration>,
}

/// The twin's bench catheter (the `bench` scene preset): 7 Fr, EI 0.6 x 10⁻³ N·m², 50 mm
/// flexible, pre-curved to a 60 mm radius.
pub const BENCH_CATHETER: &str = "twin-bench-7f";

/// The catalogue: the twin's bench catheter, and the middle of the `varied` preset's ranges (a
/// catheter known only roughly).
pub fn catalogue() -> Vec<CatalogueCatheter> {
    vec![
        CatalogueCatheter {
            name: BENCH_CATHETER.into(),
            description: "the twin's bench catheter: 7 Fr, EI 0.60 mN·m², 50 mm flexible, \
                          pre-curved to a 60 mm radius"
                .into(),
            bending_stiffness_n_m2: 0.6e-3,
            flexible_length_mm: 50.0,
            precurvature_per_mm: 1.0 / 60.0,
            diameter_mm: 2.33,
            calibration: None,
        },
        CatalogueCatheter {
            name: "twin-varied-mid-7f".into(),
            description: "the middle of the twin's `varied` catheters: 7 Fr, EI 0.65 mN·m², \
                          50 mm flexible, pre-curved to a 70 mm radius"
                .into(),
            bending_stiffness_n_m2: 0.65e-3,
            flexible_length_mm: 50.0,
            precurvature_per_mm: 1.0 / 70.0,
            diameter_mm: 2.33,
            calibration: None,
        },
    ]
}

/// A catalogue entry or a catheter file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CatheterError {
    /// No catalogue entry has this name, and no such file exists.
    #[error("no catheter `{name}` in the catalogue ({known}) and no such file")]
    Unknown {
        /// The name given.
        name: String,
        /// The catalogue's names, comma-separated.
        known: String,
    },
    /// A file could not be read.
    #[error("cannot read catheter file '{path}'")]
    Read {
        /// The file.
        path: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file is not a catheter's JSON.
    #[error(
        "catheter file '{path}' is not a catheter (JSON with name, bending_stiffness_n_m2, ...)"
    )]
    Json {
        /// The file.
        path: String,
        /// Why.
        #[source]
        source: serde_json::Error,
    },
    /// A value is outside what a catheter can have.
    #[error("catheter `{name}`: {field} = {value} is impossible ({why})")]
    Impossible {
        /// The catheter's name.
        name: String,
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
        /// The range it must lie in.
        why: &'static str,
    },
}

impl CatalogueCatheter {
    /// Whether every value is physically possible for an intravascular catheter; the error
    /// names the first field that is not.
    pub fn check(&self) -> Result<(), CatheterError> {
        let fields: [(&'static str, f64, bool, &'static str); 4] = [
            (
                "bending_stiffness_n_m2",
                self.bending_stiffness_n_m2,
                (1e-6..=1e-1).contains(&self.bending_stiffness_n_m2),
                "10⁻⁶ to 0.1 N·m²",
            ),
            (
                "flexible_length_mm",
                self.flexible_length_mm,
                (5.0..=300.0).contains(&self.flexible_length_mm),
                "5 to 300 mm",
            ),
            (
                "precurvature_per_mm",
                self.precurvature_per_mm,
                (0.0..=0.2).contains(&self.precurvature_per_mm),
                "0 (straight) to 0.2 /mm (a 5 mm radius)",
            ),
            (
                "diameter_mm",
                self.diameter_mm,
                (0.3..=6.0).contains(&self.diameter_mm),
                "0.3 to 6 mm (1 to 18 Fr)",
            ),
        ];
        match fields.into_iter().find(|(_, _, ok, _)| !ok) {
            Some((field, value, _, why)) => Err(CatheterError::Impossible {
                name: self.name.clone(),
                field,
                value,
                why,
            }),
            None => Ok(()),
        }
    }

    /// The rod the fit assumes: `template`'s solver settings with this catheter's length,
    /// diameter, pre-curvature (about the section's x axis) and stiffness.
    pub fn rod(&self, template: &RodConfig) -> RodConfig {
        RodConfig {
            length_mm: self.flexible_length_mm,
            diameter_mm: self.diameter_mm,
            precurvature_per_mm: [self.precurvature_per_mm, 0.0],
            ..template.clone()
        }
        .with_bending_stiffness(self.bending_stiffness_n_m2 * 1e6)
    }

    /// Finds `name_or_path`: a catalogue name, or a catheter file (JSON). Checked.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn find(name_or_path: &str) -> Result<Self, CatheterError> {
        let catalogue = catalogue();
        let found = match catalogue.iter().find(|c| c.name == name_or_path) {
            Some(entry) => entry.clone(),
            None => {
                let path = std::path::Path::new(name_or_path);
                if !path.exists() {
                    return Err(CatheterError::Unknown {
                        name: name_or_path.into(),
                        known: catalogue
                            .iter()
                            .map(|c| c.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", "),
                    });
                }
                let text = std::fs::read(path).map_err(|source| CatheterError::Read {
                    path: name_or_path.into(),
                    source,
                })?;
                Self::from_json(&text, name_or_path)?
            }
        };
        found.check()?;
        Ok(found)
    }

    /// A catheter file's contents (`source` names it in errors). Checked.
    pub fn from_json(bytes: &[u8], source: &str) -> Result<Self, CatheterError> {
        let catheter: Self = serde_json::from_slice(bytes).map_err(|e| CatheterError::Json {
            path: source.into(),
            source: e,
        })?;
        catheter.check()?;
        Ok(catheter)
    }
}

/// How a catheter's stiffness was calibrated from pairs with a measured force.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StiffnessCalibration {
    /// The stiffness before calibration, N·m².
    pub nominal_n_m2: f64,
    /// The factor the nominal stiffness was multiplied by.
    pub scale: f64,
    /// Pairs it was fitted on.
    pub pairs: usize,
    /// Standard error of the scale from its fit (the calibration curve's residuals).
    pub scale_sd: f64,
    /// Share of the measured forces' variance (about zero) the scaled estimates explain, 0-1.
    pub explained: f64,
}

/// Fewest labelled pairs a calibration accepts.
pub const MIN_STIFFNESS_PAIRS: usize = 3;

/// Least share of the measured forces' variance the scaled estimates must explain; below it, the
/// pairs contradict each other (or the images do not show the catheter the catalogue names).
pub const MIN_EXPLAINED: f64 = 0.5;

/// Least measured force, over all pairs, for the scale to be determined, N (RMS of the
/// measured magnitudes): unloaded pairs say nothing about the stiffness.
pub const MIN_RMS_FORCE_N: f64 = 0.02;

/// Why a calibration was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    /// Too few pairs with both a measured force and an estimate.
    #[error(
        "{usable} pairs have both a measured force and an estimate from their images; at least \
         {MIN_STIFFNESS_PAIRS} are needed"
    )]
    TooFewPairs {
        /// Usable pairs.
        usable: usize,
    },
    /// The measured forces are all near zero.
    #[error(
        "the measured forces are too small to tell the stiffness (RMS {rms_n:.3} N, at least \
         {MIN_RMS_FORCE_N} N needed): press the tip harder on some pairs"
    )]
    Unloaded {
        /// RMS magnitude of the measured forces, N.
        rms_n: f64,
    },
    /// The scaled estimates do not follow the measured forces.
    #[error(
        "the pairs contradict each other: one stiffness explains only {:.0} % of the measured \
         forces (at least {:.0} % needed); check the force labels and that the images show \
         this catheter",
        explained * 100.0,
        MIN_EXPLAINED * 100.0
    )]
    Contradictory {
        /// The share explained, 0-1.
        explained: f64,
    },
    /// The calibration curve's slope is not positive: the estimates fall as the measured forces
    /// rise.
    #[error(
        "the estimates point against the measured forces (slope {slope:.3} N estimated per N \
         measured); check the force labels' axes and signs"
    )]
    Opposed {
        /// The fitted slope `Σ m·e / Σ m·m`, newtons estimated per newton measured.
        slope: f64,
    },
}

/// Calibrates `catheter`'s stiffness from pairs of (measured force, blind physics estimate under
/// its current stiffness), N: the scale `s` of the calibration curve `estimate ≈ measured / s`,
/// fitted by least squares over the three axes (`s = Σ m·m / Σ m·e`; why this way round: the
/// module's doc). Refused with fewer than [`MIN_STIFFNESS_PAIRS`] pairs, near-zero forces, or
/// pairs one scale cannot explain.
pub fn calibrate_stiffness(
    catheter: &CatalogueCatheter,
    pairs: &[(TipForce, TipForce)],
) -> Result<CatalogueCatheter, CalibrationError> {
    if pairs.len() < MIN_STIFFNESS_PAIRS {
        return Err(CalibrationError::TooFewPairs {
            usable: pairs.len(),
        });
    }
    let pairs: Vec<([f64; 3], [f64; 3])> = pairs
        .iter()
        .map(|(measured, estimate)| (measured.to_f64(), estimate.to_f64()))
        .collect();
    let dot = |a: &[f64; 3], b: &[f64; 3]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (mut me, mut ee, mut mm) = (0.0, 0.0, 0.0);
    for (measured, estimate) in &pairs {
        me += dot(measured, estimate);
        ee += dot(estimate, estimate);
        mm += dot(measured, measured);
    }
    let rms_n = (mm / pairs.len() as f64).sqrt();
    if rms_n < MIN_RMS_FORCE_N || ee <= 0.0 {
        return Err(CalibrationError::Unloaded { rms_n });
    }
    // The curve's slope, estimate per newton measured: 1 / s.
    let slope = me / mm;
    if slope <= 0.0 {
        return Err(CalibrationError::Opposed { slope });
    }
    let scale = 1.0 / slope;
    let residual: f64 = pairs
        .iter()
        .map(|(m, e)| (0..3).map(|i| (m[i] - scale * e[i]).powi(2)).sum::<f64>())
        .sum();
    let explained = 1.0 - residual / mm;
    if explained < MIN_EXPLAINED {
        return Err(CalibrationError::Contradictory { explained });
    }
    // The slope's standard error from the curve's residuals, carried to the scale (delta method).
    let curve_residual: f64 = pairs
        .iter()
        .map(|(m, e)| (0..3).map(|i| (e[i] - slope * m[i]).powi(2)).sum::<f64>())
        .sum();
    let dof = (3 * pairs.len()).saturating_sub(1).max(1) as f64;
    let scale_sd = (curve_residual / dof / mm).sqrt() / (slope * slope);
    Ok(CatalogueCatheter {
        bending_stiffness_n_m2: catheter.bending_stiffness_n_m2 * scale,
        calibration: Some(StiffnessCalibration {
            nominal_n_m2: catheter.bending_stiffness_n_m2,
            scale,
            pairs: pairs.len(),
            scale_sd,
            explained,
        }),
        ..catheter.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_catalogue_is_possible_and_impossible_values_are_named() {
        for entry in catalogue() {
            entry.check().unwrap();
        }
        let mut bad = catalogue()[0].clone();
        bad.flexible_length_mm = -4.0;
        let text = bad.check().unwrap_err().to_string();
        assert!(
            text.contains("flexible_length_mm") && text.contains("-4"),
            "{text}"
        );
        let json = br#"{"name":"x","description":"","bending_stiffness_n_m2":2.0,
            "flexible_length_mm":50,"precurvature_per_mm":0,"diameter_mm":2.33}"#;
        let text = CatalogueCatheter::from_json(json, "x.json")
            .unwrap_err()
            .to_string();
        assert!(text.contains("bending_stiffness_n_m2"), "{text}");
        assert!(
            CatalogueCatheter::from_json(b"{}", "y.json")
                .unwrap_err()
                .to_string()
                .contains("y.json")
        );
    }

    #[test]
    fn a_stiffer_catheter_is_calibrated_and_contradictions_are_refused() {
        let nominal = catalogue()[0].clone();
        // The images under the nominal stiffness read 1/1.3 of the true forces: EI is 1.3x.
        let pairs: Vec<_> = (0..6)
            .map(|i| {
                let measured = TipForce::new(0.05 * i as f32, -0.02, -0.1 - 0.01 * i as f32);
                (measured, measured.map(|f| f / 1.3))
            })
            .collect();
        let calibrated = calibrate_stiffness(&nominal, &pairs).unwrap();
        let c = calibrated.calibration.unwrap();
        assert!((c.scale - 1.3).abs() < 1e-6 && c.explained > 0.999, "{c:?}");
        assert!((calibrated.bending_stiffness_n_m2 - 0.78e-3).abs() < 1e-9);
        // Estimates with noise of their own (a network's masks): the scale is not pulled
        // towards zero, as regressing the forces on the estimates would pull it (to 1.22 here).
        let noisy: Vec<_> = pairs
            .iter()
            .chain(&pairs)
            .enumerate()
            .map(|(i, (measured, exact))| {
                let sign = if i < pairs.len() { 1.0 } else { -1.0 };
                let noise = [0.03 * sign, -0.02 * sign, 0.015 * sign];
                let estimate = TipForce::new(
                    exact[0] + noise[0],
                    exact[1] + noise[1],
                    exact[2] + noise[2],
                );
                (*measured, estimate)
            })
            .collect();
        let c = calibrate_stiffness(&nominal, &noisy)
            .unwrap()
            .calibration
            .unwrap();
        assert!((c.scale - 1.3).abs() < 1e-5, "{c:?}");
        assert_eq!(
            calibrate_stiffness(&nominal, &pairs[..2]),
            Err(CalibrationError::TooFewPairs { usable: 2 })
        );
        let small = TipForce::new(0.001, 0.0, 0.0);
        let unloaded = vec![(small, small); 5];
        assert!(matches!(
            calibrate_stiffness(&nominal, &unloaded),
            Err(CalibrationError::Unloaded { .. })
        ));
        // Forces whose estimates point every which way: no one stiffness explains them.
        let contradictory: Vec<_> = (0..6)
            .map(|i| {
                let m = TipForce::new(0.1, -0.1, 0.2);
                let e = if i % 2 == 0 {
                    TipForce::new(0.1, 0.1, 0.0)
                } else {
                    TipForce::new(0.0, -0.1, 0.2)
                };
                (m, e)
            })
            .collect();
        let err = calibrate_stiffness(&nominal, &contradictory).unwrap_err();
        assert!(
            matches!(err, CalibrationError::Contradictory { .. }),
            "{err}"
        );
        // Labels with their signs flipped: the curve falls, and the error says by how much.
        let flipped: Vec<_> = pairs.iter().map(|(m, e)| (m.map(|f| -f), *e)).collect();
        let err = calibrate_stiffness(&nominal, &flipped).unwrap_err();
        match &err {
            CalibrationError::Opposed { slope } => {
                assert!((slope + 1.0 / 1.3).abs() < 1e-5, "{slope}")
            }
            other => panic!("{other}"),
        }
        assert!(err.to_string().contains("slope -0.769"), "{err}");
    }
}
