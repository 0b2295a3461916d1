//! `hnet eval`'s physics check: each simulated pair's catheter reconstructed in 3D from its masks
//! (the true ones, and the network's) and the tip force of the twin's rod fitted to it
//! ([`hnet_twin::reconstruction::physics_force`]), against the pair's record: the reconstruction's distance from
//! the true centreline, and Table I of the physics force beside the network's on the same pairs.
//!
//! The fit reads the masks with an [`Estimator`]: **blind** (the default) assumes a catalogue
//! catheter and fits the base from its nominal pose, with cameras rebuilt from the C-arms'
//! settings, as a user's pair would be read; **oracle** hands it each pair's recorded catheter
//! and exact base (the twin's answers), which bounds what the masks allow.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::Instant;

use hnet_model::metrics::{AXES, ForceAccumulator, ForceMetrics};
use hnet_twin::dataset::Dataset;
use hnet_twin::dataset::simulate::{SampleRecord, read_sample_record};
use hnet_twin::reconstruction::MaskOrigin;
use hnet_twin::reconstruction::catalogue::CatalogueCatheter;
use hnet_twin::reconstruction::centreline::Mask;
use hnet_twin::reconstruction::physics_force::{
    CalibrationPair, ForceCombination, PhysicsSetup, physics_estimate,
};
use hnet_twin::reconstruction::rod_fit::distances_to_rod;
use hnet_twin::simulator::carm::HeaderError;
use hnet_twin::simulator::render::PROXIMAL_SHAFT_MM;
use hnet_twin::simulator::rod;
use hnet_twin::simulator::scene::NominalBase;
use hnet_twin::vec3::Vec3;
use hnet_units::{ImageSize, TipForce};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// What the rod fit is told about each pair.
#[derive(Debug, Clone)]
pub enum Estimator {
    /// What a user has ([`BlindEstimator`]).
    Blind(Box<BlindEstimator>),
    /// The twin's answers: each pair's recorded catheter and exact base
    /// ([`SampleRecord::physics_setup`]). Bounds what the masks allow; no user has it.
    Oracle,
}

/// The blind estimator: the C-arms' settings, a catalogue `catheter`, and a `nominal_base`
/// whose position and orientation are fitted ([`PhysicsSetup::blind`]).
#[derive(Debug, Clone)]
pub struct BlindEstimator {
    /// The catheter assumed.
    pub catheter: CatalogueCatheter,
    /// Where the base fit starts, and how far it may go.
    pub nominal_base: NominalBase,
    /// How wrong each pair's recorded C-arm settings are read (the mismatch suite's geometry
    /// errors; none by default), drawn per pair from `seed`.
    pub header_error: HeaderError,
    /// Seed of those draws.
    pub seed: u64,
}

impl Estimator {
    /// `blind` or `oracle`, as tables and JSON name it.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Blind(_) => "blind",
            Self::Oracle => "oracle",
        }
    }

    /// How the estimator reads `record`'s masks at `size` (the `pair`-th pair checked).
    pub fn setup(&self, record: &SampleRecord, size: ImageSize, pair: usize) -> PhysicsSetup {
        match self {
            Self::Blind(blind) => record.blind_setup_misread(
                size,
                &blind.catheter,
                &blind.nominal_base,
                &blind.header_error,
                blind.seed.wrapping_add(pair as u64),
            ),
            Self::Oracle => record.physics_setup(size),
        }
    }
}

/// The estimator in a sentence, for table captions: blind with the `catheter` it assumed, or the
/// oracle (`None`).
pub fn estimator_caption(catheter: Option<&CatalogueCatheter>) -> String {
    match catheter {
        Some(catheter) => format!(
            "blind (catheter `{}` assumed, base fitted from its nominal pose, C-arms from their \
             settings; nothing of each pair's own record)",
            catheter.name
        ),
        None => "ORACLE (each pair's recorded catheter and exact base: the twin's answers, which \
                 no user has)"
            .into(),
    }
}

/// The physics check over one split, from one kind of masks.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PhysicsEvaluation {
    /// Which masks.
    pub masks: MaskOrigin,
    /// Their size: the dataset's own for the true masks, the network's input for its masks.
    pub size: ImageSize,
    /// Pairs tried.
    pub pairs: usize,
    /// Pairs reconstructed and fitted.
    pub fitted: usize,
    /// Views of the fitted pairs whose mask had blobs set aside beside the catheter (another
    /// device, or the background read as catheter: `hnet_twin::reconstruction::centreline`).
    #[serde(default)]
    pub views_with_blobs_set_aside: usize,
    /// Pairs that failed, by the step that failed (`centreline: not a tube`, `reconstruction`,
    /// `fit`, ...: `PhysicsError::counted_as`).
    pub failures: BTreeMap<String, usize>,
    /// Mean distance of the reconstructed points from the true centreline (its flexible section
    /// and the straight shaft behind the base), mean over fitted pairs, mm.
    pub centreline_error_mm: Option<f64>,
    /// Mean distance of the reconstructed tip from the true tip, over fitted pairs whose tip was
    /// seen in both views, mm.
    pub tip_error_mm: Option<f64>,
    /// Table I of the fitted rod's tip force.
    pub force: Option<ForceMetrics>,
    /// Table I of the network's force on the same pairs, when it estimates one.
    pub network_force: Option<ForceMetrics>,
    /// Table I of the network's force combined with the physics estimate on the same pairs
    /// ([`ForceCombination::combine`], with [`Self::combination`]), for the network's own masks
    /// when it estimates a force and a combination was calibrated.
    #[serde(default)]
    pub combined_force: Option<ForceMetrics>,
    /// Share of pairs per axis whose true force lies within the combined estimate's nominal
    /// 90 % interval ([`ForceCombination::interval_90_n`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub combined_coverage_90: Option<[f64; 3]>,
    /// The calibration the combined force used (measured on other pairs than these).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub combination: Option<ForceCombination>,
    /// Pearson correlation of the network's and the physics estimate's Fz errors on the same
    /// pairs, for the network's own masks: the combined estimate's inverse-variance weights
    /// assume it near 0.
    #[serde(default)]
    pub fz_error_correlation: Option<f64>,
    /// Wall time per pair (centrelines, reconstruction and fit; all cores), ms.
    pub millis_per_pair: f64,
    /// The fitted rod's tip force per pair, in the order of the pairs checked (`None` where the
    /// pair could not be fitted). Kept out of the JSON; `hnet eval` writes it per pair.
    #[serde(skip)]
    pub force_per_pair: Vec<Option<PhysicsForce>>,
}

impl PhysicsEvaluation {
    /// The calibration pairs these checks give: every fitted pair with a network force and a
    /// standard error.
    pub fn calibration_pairs(&self, pairs: &[PairToCheck<'_>]) -> Vec<CalibrationPair> {
        pairs
            .iter()
            .zip(&self.force_per_pair)
            .filter_map(|(pair, physics)| {
                let physics = physics.as_ref()?;
                Some(CalibrationPair {
                    truth_n: pair.truth_n,
                    network_n: pair.network_n?,
                    physics_n: physics.force_n,
                    physics_sd_n: physics.sd_n?,
                })
            })
            .collect()
    }
}

/// One pair's physics estimate: the fitted rod's tip force and the fit's standard error, N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicsForce {
    /// The tip force, N.
    pub force_n: TipForce,
    /// Its standard error from the fit ([`hnet_twin::reconstruction::rod_fit::RodFit::force_sd_n`]), N.
    pub sd_n: Option<[f32; 3]>,
    /// The correlations of its errors between axes, x-y, x-z, y-z
    /// ([`hnet_twin::reconstruction::rod_fit::RodFit::force_correlation`]).
    pub correlation: Option<[f32; 3]>,
}

/// One pair to check.
pub struct PairToCheck<'a> {
    /// Its true force, N.
    pub truth_n: TipForce,
    /// The network's force, N, when it has one.
    pub network_n: Option<TipForce>,
    /// The masks of view A and B to reconstruct from.
    pub masks: [Mask<'a>; 2],
}

/// The records of `pairs`, or `None` when the dataset was not simulated (imported or exported
/// by the page: nothing to check against).
pub fn read_records(dataset: &Dataset, ids: &[&str]) -> Option<Vec<SampleRecord>> {
    ids.par_iter()
        .map(|id| read_sample_record(dataset, id).ok())
        .collect()
}

/// Mean distance of `points` from the true rod of `record`, mm.
fn distance_from_truth(record: &SampleRecord, points: &[Vec3]) -> Option<f64> {
    let (config, base) = record.scene.rod(&record.rod);
    let truth = rod::solve(&config, &base, record.scene.tip_force_n.into()).ok()?;
    let d = distances_to_rod(&truth, PROXIMAL_SHAFT_MM, points);
    (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
}

/// What one pair gave.
enum Outcome {
    Fitted {
        physics: PhysicsForce,
        centreline_error_mm: Option<f64>,
        tip_error_mm: Option<f64>,
        /// Of its two views, how many had blobs set aside.
        views_with_blobs_set_aside: usize,
    },
    /// [`hnet_twin::reconstruction::physics_force::PhysicsError::counted_as`].
    Failed(String),
}

/// Checks `pairs` (with their `records`; masks all of `size`) from the masks `origin`; with a
/// `combination`, the network's force is combined with the physics estimate from its own masks.
pub fn check(
    origin: MaskOrigin,
    size: ImageSize,
    pairs: &[PairToCheck<'_>],
    records: &[SampleRecord],
    estimator: &Estimator,
    combination: Option<&ForceCombination>,
) -> PhysicsEvaluation {
    let started = Instant::now();
    let outcomes: Vec<Outcome> = pairs
        .par_iter()
        .zip(records)
        .enumerate()
        .map(|(index, (pair, record))| {
            match physics_estimate(pair.masks, &estimator.setup(record, size, index)) {
                Ok(estimate) => {
                    let reconstruction = &estimate.reconstruction;
                    Outcome::Fitted {
                        physics: PhysicsForce {
                            force_n: estimate.fit.force_n,
                            sd_n: estimate.fit.force_sd_n,
                            correlation: estimate.fit.force_correlation,
                        },
                        centreline_error_mm: distance_from_truth(record, &reconstruction.points_mm),
                        tip_error_mm: reconstruction
                            .tip_seen
                            .then(|| record.tip_mm())
                            .flatten()
                            .map(|tip| (reconstruction.last_mm() - tip).norm()),
                        views_with_blobs_set_aside: estimate
                            .centrelines
                            .iter()
                            .filter(|c| !c.set_aside_px.is_empty())
                            .count(),
                    }
                }
                Err(e) => Outcome::Failed(e.counted_as()),
            }
        })
        .collect();
    let millis_per_pair = started.elapsed().as_secs_f64() * 1e3 / pairs.len().max(1) as f64;

    let mut failures = BTreeMap::new();
    let (mut physics, mut network, mut combined) = (
        ForceAccumulator::new(),
        ForceAccumulator::new(),
        ForceAccumulator::new(),
    );
    let (mut centreline, mut tip) = (Vec::new(), Vec::new());
    let mut set_aside = 0;
    // (network, physics) Fz errors, N, for the correlation.
    let mut fz_errors = Vec::new();
    // Pairs whose truth lies in the combined 90 % interval, per axis.
    let mut covered = [0usize; 3];
    for (pair, outcome) in pairs.iter().zip(&outcomes) {
        match outcome {
            Outcome::Fitted {
                physics: fitted,
                centreline_error_mm,
                tip_error_mm,
                views_with_blobs_set_aside,
            } => {
                set_aside += views_with_blobs_set_aside;
                let force_n = fitted.force_n;
                physics.push(force_n, pair.truth_n);
                if let Some(n) = pair.network_n {
                    network.push(n, pair.truth_n);
                    // Combined only with the physics estimate from the network's own masks,
                    // the case it is for (from true masks the physics estimate is near exact).
                    if origin == MaskOrigin::Predicted {
                        if let Some(c) = combination {
                            let (force, sd) = c.combine_with_sd(n, force_n, fitted.sd_n);
                            combined.push(force, pair.truth_n);
                            let half = c.interval_90_n(sd);
                            for axis in 0..3 {
                                let off = (force[axis] - pair.truth_n[axis]).abs();
                                covered[axis] += usize::from(off <= half[axis]);
                            }
                        }
                        let truth = f64::from(pair.truth_n[2]);
                        fz_errors.push((f64::from(n[2]) - truth, f64::from(force_n[2]) - truth));
                    }
                }
                centreline.extend(*centreline_error_mm);
                tip.extend(*tip_error_mm);
            }
            Outcome::Failed(step) => *failures.entry(step.clone()).or_insert(0) += 1,
        }
    }
    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    PhysicsEvaluation {
        masks: origin,
        size,
        pairs: pairs.len(),
        fitted: physics.len() as usize,
        views_with_blobs_set_aside: set_aside,
        failures,
        centreline_error_mm: mean(&centreline),
        tip_error_mm: mean(&tip),
        force: physics.finish(),
        network_force: network.finish(),
        combined_coverage_90: (!combined.is_empty())
            .then(|| covered.map(|n| n as f64 / combined.len() as f64)),
        combined_force: combined.finish(),
        combination: combination
            .copied()
            .filter(|_| origin == MaskOrigin::Predicted && !combined.is_empty()),
        fz_error_correlation: correlation(&fz_errors),
        millis_per_pair,
        force_per_pair: outcomes
            .iter()
            .map(|outcome| match outcome {
                Outcome::Fitted { physics, .. } => Some(*physics),
                Outcome::Failed(_) => None,
            })
            .collect(),
    }
}

/// Pearson correlation of paired values; `None` for fewer than 3 pairs or a constant side.
fn correlation(pairs: &[(f64, f64)]) -> Option<f64> {
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(x, y), (a, b)| (x + a / n, y + b / n));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in pairs {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

/// The physics check as markdown.
pub fn markdown(checks: &[PhysicsEvaluation]) -> String {
    let mut s = String::new();
    if checks.is_empty() {
        return s;
    }
    let _ = writeln!(
        s,
        "\n3D reconstruction and physics-checked force (the twin's rod fitted to the catheter \
         reconstructed from both masks)\n"
    );
    let _ = writeln!(
        s,
        "| masks | fitted | centreline error (mm) | tip error (mm) | R² Fx / Fy / Fz, physics | \
         R² Fx / Fy / Fz, network, same pairs | R² Fx / Fy / Fz, combined | 90 % interval \
         covers Fx / Fy / Fz | failures | ms per pair |"
    );
    let _ = writeln!(
        s,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    let r2 = |m: &Option<ForceMetrics>| match m {
        Some(m) => AXES
            .iter()
            .enumerate()
            .map(|(i, _)| m.axes[i].r2.map_or("n/a".into(), |v| format!("{v:.3}")))
            .collect::<Vec<_>>()
            .join(" / "),
        None => "n/a".into(),
    };
    let mm = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.3}"));
    for c in checks {
        let failures = if c.failures.is_empty() {
            "none".to_string()
        } else {
            c.failures
                .iter()
                .map(|(step, n)| format!("{n} at {step}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(
            s,
            "| {} ({}) | {} of {}{} | {} | {} | {} | {} | {} | {} | {} | {:.0} |",
            c.masks.row_name(),
            c.size,
            c.fitted,
            c.pairs,
            match c.views_with_blobs_set_aside {
                0 => String::new(),
                n => format!(" ({n} views with blobs set aside)"),
            },
            mm(c.centreline_error_mm),
            mm(c.tip_error_mm),
            r2(&c.force),
            r2(&c.network_force),
            r2(&c.combined_force),
            c.combined_coverage_90.map_or("n/a".into(), |v| v
                .map(|share| format!("{:.0} %", share * 100.0))
                .join(" / ")),
            failures,
            c.millis_per_pair
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use hnet_twin::dataset::simulate::simulate_dataset;
    use hnet_twin::simulator::scene::{Backgrounds, Modality, TwinConfig};

    /// Bench pairs whose true masks stand in for a network's, its force the truth 0.05 N off on
    /// every axis: each fitted pair gets its physics force and standard error, and the combined
    /// estimate is reported for the network's masks only.
    #[test]
    fn the_network_force_is_combined_with_the_physics_estimate_from_its_own_masks() {
        let root = std::env::temp_dir().join(format!("hnet-physics-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let twin = TwinConfig::new(Modality::Xray2, ImageSize::square(128));
        let backgrounds = Backgrounds::phantom(&twin.views);
        let names = ["phantom:+0/+0".to_string(), "phantom:+90/+0".to_string()];
        simulate_dataset(&twin, &backgrounds, &names, 4, 11, &root, &|_| {}).unwrap();
        let dataset = Dataset::open(&root).unwrap();
        let loaded: Vec<_> = dataset
            .rows
            .iter()
            .map(|row| dataset.load_pair(row, None).unwrap())
            .collect();
        let ids: Vec<&str> = dataset.rows.iter().map(|row| row.id.as_str()).collect();
        let records = read_records(&dataset, &ids).unwrap();
        let size = dataset.header.image_size;
        let truth: Vec<TipForce> = dataset.rows.iter().map(|row| row.force_n).collect();
        let pairs: Vec<PairToCheck> = loaded
            .iter()
            .zip(&truth)
            .map(|(pair, truth)| PairToCheck {
                truth_n: *truth,
                network_n: Some(truth.map(|f| f + 0.05)),
                masks: [&pair.mask_a, &pair.mask_b].map(|m| Mask::soft(size.width, size.height, m)),
            })
            .collect();

        let combination = ForceCombination {
            network_error_n: [0.05; 3],
            physics_sd_scale: 3.0,
            pairs: 10,
            interval_90_sd: [1.645; 3],
            network_interval_90_n: None,
            stack: None,
        };
        let network = check(
            MaskOrigin::Predicted,
            size,
            &pairs,
            &records,
            &Estimator::Oracle,
            Some(&combination),
        );
        assert_eq!(network.fitted, 4, "{:?}", network.failures);
        assert_eq!(network.combined_force.as_ref().unwrap().samples, 4);
        assert_eq!(network.combination, Some(combination));
        assert_eq!(network.calibration_pairs(&pairs).len(), 4);
        assert!(
            network
                .fz_error_correlation
                .is_some_and(|r| (-1.0..=1.0).contains(&r))
        );
        for ((physics, pair), truth) in network.force_per_pair.iter().zip(&pairs).zip(&truth) {
            let physics = physics.unwrap();
            let combined =
                combination.combine(pair.network_n.unwrap(), physics.force_n, physics.sd_n);
            // From exact masks the fit is tight (its standard error well under the network's
            // 0.05 N), so the combination stays near the physics estimate and the truth.
            for axis in 0..3 {
                let sd = physics.sd_n.unwrap()[axis];
                assert!(sd > 0.0 && sd * 3.0 < 0.05, "{physics:?}");
                assert!(
                    (combined[axis] - truth[axis]).abs() < 0.02,
                    "{combined:?} {truth:?}"
                );
            }
        }
        let without = check(
            MaskOrigin::Predicted,
            size,
            &pairs,
            &records,
            &Estimator::Oracle,
            None,
        );
        assert!(without.combined_force.is_none() && without.combination.is_none());
        let from_truth = check(
            MaskOrigin::Labels,
            size,
            &pairs,
            &records,
            &Estimator::Oracle,
            Some(&combination),
        );
        assert_eq!(from_truth.fitted, 4);
        assert!(from_truth.combined_force.is_none() && from_truth.combination.is_none());
        assert_eq!(from_truth.fz_error_correlation, None);
        // The correlation itself: perfectly together, opposed, and too few pairs.
        assert!((correlation(&[(1.0, 2.0), (2.0, 4.1), (3.0, 6.0)]).unwrap() - 1.0).abs() < 1e-3);
        assert!((correlation(&[(1.0, 3.0), (2.0, 2.0), (3.0, 1.0)]).unwrap() + 1.0).abs() < 1e-9);
        assert_eq!(correlation(&[(1.0, 3.0), (2.0, 2.0)]), None);
        let _ = std::fs::remove_dir_all(&root);
    }
}
