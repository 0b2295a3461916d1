//! What a weights file says about its network beyond its parameters: what its force was trained
//! on, and how far off its force is where that was measured, with the calibration of its
//! combination with the physics estimate. `hnet train` writes the first and `hnet eval --record`
//! the second into the file's provenance, under [`FACTS_KEY`] as JSON. The page and the command
//! line read them from whatever weights are loaded. Files written before facts existed still
//! load, with the figures unknown.

use std::collections::BTreeMap;

use hnet_units::mask::MaskAveraging;
use serde::{Deserialize, Serialize};

use crate::reconstruction::physics_force::ForceCombination;
use crate::simulator::carm::Biplane;
use crate::simulator::scene::{Modality, SceneSampling};

/// The provenance entry that holds a weights file's [`ModelFacts`].
pub const FACTS_KEY: &str = "facts";

/// The facts a weights file carries.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelFacts {
    /// The twin data its force head was trained on, when that was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_domain: Option<ForceDomain>,
    /// Its force error measured on held-out pairs, when `hnet eval --record` measured it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured: Option<MeasuredForce>,
}

/// The twin data a force head was trained on: the range outside which its error was never
/// measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForceDomain {
    /// The dataset (its folder's name) the range was read from.
    pub data: String,
    /// The images' modality.
    pub modality: Modality,
    /// The scene ranges (catheter, base pose, force).
    pub scenes: SceneSampling,
    /// The C-arm angles of views A and B, degrees: `[primary, secondary]`.
    pub views_deg: [[f64; 2]; 2],
    /// Whether every X-ray background was cut from the built-in thorax phantom.
    pub phantom_backgrounds: bool,
}

/// A force head's error where it was measured, and its calibrated combination.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasuredForce {
    /// The dataset (its folder's name) and split evaluated.
    pub data: String,
    /// The split evaluated.
    pub split: String,
    /// Pairs evaluated.
    pub pairs: usize,
    /// How the physics estimate read them: `blind` or `oracle`.
    pub estimator: String,
    /// How the network read each view for its masks (absent in files: one reading). The page
    /// and `hnet trace` read views the same way, so that the calibration holds.
    #[serde(default, skip_serializing_if = "MaskAveraging::is_single")]
    pub mask_averaging: MaskAveraging,
    /// The force head's mean square error per axis (x, y, z), N².
    pub head_mse_n2: [f32; 3],
    /// The share of the evaluated pairs whose true force the force head's own 90 % interval
    /// held, per axis ([`ForceCombination::head_interval_90_n`]), when a combination was
    /// calibrated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_coverage_90: Option<[f32; 3]>,
    /// The combined estimate, when one was calibrated and evaluated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub combined: Option<MeasuredCombination>,
    /// The command that measured it.
    pub command: String,
}

/// The combined estimate's calibration and its error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasuredCombination {
    /// The calibration (its own pair count included).
    pub combination: ForceCombination,
    /// The dataset (its folder's name) and split it was calibrated on.
    pub calibration_data: String,
    /// Pairs of the evaluated split with a combined estimate.
    pub pairs: usize,
    /// Its mean square error per axis, N².
    pub mse_n2: [f32; 3],
    /// The share of those pairs whose true force its 90 % interval held, per axis.
    pub coverage_90: Option<[f32; 3]>,
}

/// Facts that cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("the weights' facts (provenance entry `{FACTS_KEY}`) cannot be read")]
pub struct FactsError(#[source] serde_json::Error);

impl ModelFacts {
    /// The facts in a weights file's `provenance`; empty facts for files without them.
    pub fn read(provenance: &BTreeMap<String, String>) -> Result<Self, FactsError> {
        provenance
            .get(FACTS_KEY)
            .map_or(Ok(Self::default()), |json| {
                serde_json::from_str(json).map_err(FactsError)
            })
    }

    /// Writes the facts into `provenance`, replacing any there.
    pub fn write(&self, provenance: &mut BTreeMap<String, String>) {
        let json = serde_json::to_string(self).expect("facts serialise");
        provenance.insert(FACTS_KEY.to_string(), json);
    }

    /// Root-mean-square length of the force head's error vector, N (a bound on the RMS error
    /// of the magnitude |F|), when measured.
    pub fn head_error_n(&self) -> Option<f32> {
        self.measured
            .as_ref()
            .map(|m| error_length_n(m.head_mse_n2))
    }

    /// The same for the combined estimate, when measured.
    pub fn combined_error_n(&self) -> Option<f32> {
        let combined = self.measured.as_ref()?.combined.as_ref()?;
        Some(error_length_n(combined.mse_n2))
    }

    /// The calibrated combination with the physics estimate, when measured.
    pub fn combination(&self) -> Option<&ForceCombination> {
        Some(&self.measured.as_ref()?.combined.as_ref()?.combination)
    }

    /// How the network read each view where its force was measured and its combination
    /// calibrated: how the page and `hnet trace` read views with these weights. One reading
    /// when nothing was measured.
    pub fn mask_averaging(&self) -> MaskAveraging {
        self.measured
            .as_ref()
            .map_or(MaskAveraging::Single, |m| m.mask_averaging)
    }
}

/// The name a file or folder is recorded by in a weights file's facts and in a force trace: its
/// last component (no machine's folders).
pub fn recorded_name(path: &std::path::Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// The root-mean-square length of an error vector whose per-axis mean square errors are
/// `mse_n2` (N²), newtons.
pub fn error_length_n(mse_n2: [f32; 3]) -> f32 {
    mse_n2.iter().sum::<f32>().sqrt()
}

/// How far a view's C-arm angles (primary or secondary), degrees, may lie from the ones a force
/// head was trained at and still count as its view.
pub const VIEW_ANGLE_TOLERANCE_DEG: f64 = 0.5;

impl ForceDomain {
    /// The views of `views` whose C-arm angles differ from the trained ones by more than
    /// [`VIEW_ANGLE_TOLERANCE_DEG`], one phrase each (`view A at -20°/+10° (trained at
    /// +0°/+0°)`); empty at the trained angles. Where they differ, the force head alone gives no
    /// estimate ([`ForceCombination::estimate_at`]).
    pub fn view_departures(&self, views: &Biplane) -> Vec<String> {
        let mut departures = Vec::new();
        for (letter, (view, trained)) in ["A", "B"]
            .iter()
            .zip([views.a, views.b].iter().zip(self.views_deg))
        {
            let angles = [view.primary_deg, view.secondary_deg];
            if (angles[0] - trained[0]).abs() > VIEW_ANGLE_TOLERANCE_DEG
                || (angles[1] - trained[1]).abs() > VIEW_ANGLE_TOLERANCE_DEG
            {
                departures.push(format!(
                    "view {letter} at {:+.0}°/{:+.0}° (trained at {:+.0}°/{:+.0}°)",
                    angles[0], angles[1], trained[0], trained[1]
                ));
            }
        }
        departures
    }

    /// The domain of a twin dataset, from its header's `source` (what `hnet simulate` records),
    /// named `data`; `None` for a dataset the twin did not make.
    pub fn of_twin_source(data: &str, source: &serde_json::Value) -> Option<Self> {
        let twin = &source["twin"];
        let modality = serde_json::from_value(twin["modality"].clone()).ok()?;
        let scenes = serde_json::from_value(twin["scene"].clone()).ok()?;
        let angle = |view: &str, key: &str| twin["views"][view][key].as_f64();
        let views_deg = [
            [angle("a", "primary_deg")?, angle("a", "secondary_deg")?],
            [angle("b", "primary_deg")?, angle("b", "secondary_deg")?],
        ];
        let backgrounds = source["backgrounds"].as_array();
        let phantom_backgrounds = backgrounds.is_some_and(|b| {
            !b.is_empty()
                && b.iter()
                    .all(|s| s.as_str().is_some_and(|s| s.starts_with("phantom:")))
        });
        Some(Self {
            data: data.to_string(),
            modality,
            scenes,
            views_deg,
            phantom_backgrounds,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn facts_round_trip_through_a_provenance_and_older_files_have_none() {
        let mut provenance = BTreeMap::from([("seed".to_string(), "42".to_string())]);
        assert_eq!(
            ModelFacts::read(&provenance).unwrap(),
            ModelFacts::default()
        );
        let facts = ModelFacts {
            force_domain: Some(ForceDomain {
                data: "xray2-bench-224-s7".into(),
                modality: Modality::Xray2,
                scenes: SceneSampling::bench(),
                views_deg: [[0.0, 0.0], [90.0, 0.0]],
                phantom_backgrounds: true,
            }),
            measured: Some(MeasuredForce {
                data: "xray2-bench-224-s33".into(),
                split: "train".into(),
                pairs: 480,
                estimator: "blind".into(),
                mask_averaging: MaskAveraging::Mirrored,
                head_mse_n2: [0.0048, 0.0051, 0.0037],
                head_coverage_90: None,
                combined: None,
                command: "hnet eval".into(),
            }),
        };
        facts.write(&mut provenance);
        assert_eq!(ModelFacts::read(&provenance).unwrap(), facts);
        assert_eq!(facts.mask_averaging(), MaskAveraging::Mirrored);
        // One reading is left out of the file, and a file without the field reads as one.
        let mut single = facts.clone();
        single.measured.as_mut().unwrap().mask_averaging = MaskAveraging::Single;
        let mut written = BTreeMap::new();
        single.write(&mut written);
        assert!(!written[FACTS_KEY].contains("mask_averaging"));
        assert_eq!(ModelFacts::read(&written).unwrap(), single);
        assert_eq!(
            ModelFacts::default().mask_averaging(),
            MaskAveraging::Single
        );
        assert!((facts.head_error_n().unwrap() - 0.1166).abs() < 1e-3);
        assert_eq!(facts.combination(), None);
        provenance.insert(FACTS_KEY.into(), "{".into());
        let error = ModelFacts::read(&provenance).unwrap_err();
        assert!(error.to_string().contains("`facts`"), "{error}");
    }
}

/// What a fine-tune adds to the provenance of the weights it writes (the page's "Fine-tune on
/// my pairs" and `hnet fine-tune`).
#[derive(Debug, Clone, PartialEq)]
pub struct FineTuneRecord<'a> {
    /// How it was made (the command line, or the page's button).
    pub command: &'a str,
    /// The weights file it started from.
    pub from: &'a str,
    /// The pairs it learned from, in words.
    pub on: String,
    /// Its best epoch, from 1.
    pub best_epoch: usize,
    /// The starting network on the held-back pairs, in words.
    pub before: String,
    /// The best epoch's network on them.
    pub after: String,
}

/// The provenance of fine-tuned weights: the starting file's, without its [`FACTS_KEY`] entry
/// (its force errors and calibration were measured on the network before it was fine-tuned and
/// no longer hold: `hnet eval --record` measures the new one), with the fine-tune's own entries.
pub fn fine_tuned_provenance(
    start: &BTreeMap<String, String>,
    record: FineTuneRecord<'_>,
) -> BTreeMap<String, String> {
    let mut provenance: BTreeMap<String, String> = start
        .iter()
        .filter(|(key, _)| key.as_str() != FACTS_KEY)
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    for (key, value) in [
        ("command", record.command.to_string()),
        ("fine_tuned_from", record.from.to_string()),
        ("fine_tuned_on", record.on),
        ("fine_tune_best_epoch", record.best_epoch.to_string()),
        ("held_back_before", record.before),
        ("held_back_after", record.after),
    ] {
        provenance.insert(key.to_string(), value);
    }
    provenance
}
