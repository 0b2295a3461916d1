//! What a tip-force estimate can be said to show: its magnitude against the ablation band, no more
//! than the weights' accuracy supports, and nothing at all for a twin pair outside the data the
//! weights were trained on; and whether H-Net's estimate and the physics estimate (the rod fitted
//! to the catheter in 3D, [`crate::catheter_3d`]) disagree beyond what their errors explain.

use hnet_twin::model_facts::{ForceDomain, ModelFacts};
use hnet_twin::reconstruction::centreline::{CentrelineSettings, Mask, catheter_seen};
use hnet_twin::reconstruction::physics_force::{ForceCombination, TipForceEstimate};
use hnet_twin::simulator::scene::{Modality, SceneParams};

use crate::workspace::{LabeledPair, PairSource};
use hnet_units::{ImageSize, TipForce};

/// Why no force is read from a pair whose masks (catheter probabilities of views A and B, `size`
/// pixels) do not both show a catheter ([`catheter_seen`]: enough catheter pixels, and
/// not too many, in one blob long enough for a catheter, smaller blobs beside it set aside); `None`
/// when both do. The same rule as `hnet study no-catheter` measures.
pub fn no_catheter_found(mask_a: &[f32], mask_b: &[f32], size: ImageSize) -> Option<String> {
    let settings = CentrelineSettings::default();
    [(mask_a, "A"), (mask_b, "B")]
        .into_iter()
        .find_map(|(mask, view)| {
            catheter_seen(&Mask::soft(size.width, size.height, mask), view, &settings).err()
        })
        .map(|why| hnet_units::with_causes(&why))
}

/// Contact forces of ablation within this band (newtons) are considered effective and safe
/// (the paper: ablation needs 0.1-0.3 N at the tip).
pub const ABLATION_BAND_N: [f32; 2] = [0.1, 0.3];

/// Where a force magnitude lies against the ablation band.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BandPosition {
    /// Below 0.1 N.
    Below,
    /// 0.1-0.3 N.
    Within,
    /// Above 0.3 N.
    Above,
}

impl BandPosition {
    /// The position of `magnitude_n` (newtons).
    pub fn of(magnitude_n: f32) -> Self {
        if magnitude_n < ABLATION_BAND_N[0] {
            Self::Below
        } else if magnitude_n <= ABLATION_BAND_N[1] {
            Self::Within
        } else {
            Self::Above
        }
    }

    /// In words.
    pub fn phrase(self) -> &'static str {
        match self {
            Self::Below => "below the 0.1–0.3 N ablation band",
            Self::Within => "within the 0.1–0.3 N ablation band",
            Self::Above => "above the 0.1–0.3 N ablation band",
        }
    }
}

/// What a set of weights' force was trained on, and how far off it is there: read from the
/// facts the weights file carries ([`ModelFacts`], written by `hnet train` and `hnet eval
/// --record`), never from constants of the page.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingDomain {
    /// The twin data the force head learned from.
    pub domain: ForceDomain,
    /// How the weights' force and the physics estimate from their masks are combined, with both
    /// estimates' 90 % intervals, measured on calibration pairs.
    pub combination: ForceCombination,
    /// Root-mean-square length of the force head's error vector on held-out pairs, N.
    pub head_error_n: f32,
    /// The same for the combined estimate, N, when measured.
    pub combined_error_n: Option<f32>,
}

impl TrainingDomain {
    /// The domain of weights whose `facts` record both the data their force was trained on and
    /// a calibrated combination; `None` otherwise (their accuracy is then unknown to the page).
    pub fn of_facts(facts: &ModelFacts) -> Option<Self> {
        Some(Self {
            domain: facts.force_domain.clone()?,
            combination: *facts.combination()?,
            head_error_n: facts.head_error_n()?,
            combined_error_n: facts.combined_error_n(),
        })
    }

    /// The estimate of a pair from H-Net's force `hnet_n` and, where the rod was fitted to
    /// H-Net's own masks, the physics estimate (its force and its fit's standard error, N):
    /// [`ForceCombination::estimate`], the rule `hnet eval` and `hnet trace` follow.
    pub fn estimate(
        &self,
        hnet_n: TipForce,
        physics: Option<(TipForce, Option<[f32; 3]>)>,
    ) -> TipForceEstimate {
        self.combination.estimate(hnet_n, physics)
    }

    /// How a pair lies outside this domain, one phrase each (empty for twin pairs inside it).
    /// Uploaded images and DICOM frames are outside it by definition: the weights' error was
    /// measured on twin images, and nothing says how far real ones differ; a DICOM frame's
    /// C-arm angles, known from its headers, are compared too.
    pub fn departures(&self, pair: &LabeledPair) -> Vec<String> {
        let not_twin = || {
            format!(
                "images that are not the twin's (the error of these weights was measured on twin \
                 {} images)",
                self.domain.modality.name()
            )
        };
        let (views, settings) = match &pair.source {
            PairSource::Twin {
                views, settings, ..
            } => (views, settings),
            PairSource::Dicom { views, .. } => {
                let mut departures = vec![not_twin()];
                departures.extend(self.domain.view_departures(views));
                return departures;
            }
            PairSource::Upload { .. } => return vec![not_twin()],
        };
        let (Some(modality), Some(scene)) = (twin_modality(settings), twin_scene(settings)) else {
            return vec![UNREADABLE_SETTINGS.into()];
        };
        let mut departures = Vec::new();
        if modality != self.domain.modality {
            departures.push(format!(
                "{} images (trained on {} only)",
                modality.name(),
                self.domain.modality.name()
            ));
        }
        departures.extend(self.domain.scenes.departures(&scene));
        departures.extend(self.domain.view_departures(views));
        let source = settings["background"]["source"].as_str();
        if self.domain.phantom_backgrounds
            && modality.is_xray()
            && !source.is_some_and(|s| s.starts_with("phantom:"))
        {
            departures.push(format!(
                "a background cut from {} (trained on the built-in phantom only)",
                source.unwrap_or("an unknown radiograph")
            ));
        }
        departures
    }

    /// How `pair` departs from what the force head was trained on, one phrase each: the C-arm
    /// angles of a twin pair's and a DICOM frame's views and of an upload's stated ones (an
    /// upload that states none is read with the default biplane, at which these weights may
    /// have been trained); for a twin pair also its catheter and pose (never its force: that is
    /// what is estimated). There the head's R² was below zero (docs/results.md: -2.0 at the
    /// page's other C-arm angles, -1.3 with other catheters and poses), so where a pair departs
    /// so, the head's force is not shown on its own ([`Self::estimate_at`]). Other departures
    /// (another modality, a radiograph background) leave it shown with no verdict: its error
    /// there was not measured below zero.
    pub fn head_departures(&self, pair: &LabeledPair) -> Vec<String> {
        match &pair.source {
            PairSource::Twin {
                views, settings, ..
            } => {
                let Some(scene) = twin_scene(settings) else {
                    return vec![UNREADABLE_SETTINGS.into()];
                };
                let mut departures = self.domain.scenes.catheter_departures(&scene);
                departures.extend(self.domain.view_departures(views));
                departures
            }
            PairSource::Dicom { views, .. } => self.domain.view_departures(views),
            PairSource::Upload { views, .. } => self
                .domain
                .view_departures(&views.unwrap_or_else(crate::catheter_3d::default_views)),
        }
    }

    /// [`Self::estimate`] for `pair`: no estimate, and why, where it would be the force head
    /// alone on a pair unlike those it was trained on ([`Self::head_departures`],
    /// [`hnet_twin::reconstruction::physics_force::ForceCombination::estimate_at`]).
    pub fn estimate_at(
        &self,
        hnet_n: TipForce,
        physics: Option<(TipForce, Option<[f32; 3]>)>,
        pair: &LabeledPair,
    ) -> Result<TipForceEstimate, String> {
        self.combination
            .estimate_at(hnet_n, physics, &self.head_departures(pair))
    }
}

/// What a departure says of twin settings that cannot be read.
const UNREADABLE_SETTINGS: &str = "the pair's twin settings cannot be read";

/// A twin pair's modality, from its recorded settings.
fn twin_modality(settings: &serde_json::Value) -> Option<Modality> {
    settings["modality"].as_str().and_then(Modality::parse)
}

/// A twin pair's scene, from its recorded settings.
fn twin_scene(settings: &serde_json::Value) -> Option<SceneParams> {
    serde_json::from_value(settings["scene"].clone()).ok()
}

/// What the page says about an estimated magnitude.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// The magnitude's whole range within the estimate's 90 % intervals lies on one side of the
    /// band's edges.
    Clear {
        /// Where.
        position: BandPosition,
        /// The range of |F| over the intervals, N ([`TipForceEstimate::magnitude_range_n`]).
        range_n: (f32, f32),
    },
    /// Within its intervals, the estimate could lie on either side of an edge of the band.
    Unclear {
        /// The range of |F| over the intervals, N.
        range_n: (f32, f32),
    },
    /// Weights whose accuracy is not known (no facts recorded in their file).
    UnknownAccuracy,
    /// A pair outside what the weights were trained on (uploads included).
    OutsideTraining(Vec<String>),
}

impl Verdict {
    /// The verdict on `estimate` of `pair` from weights trained on `domain` (`None`: weights
    /// whose accuracy is unknown).
    pub fn of(
        estimate: &TipForceEstimate,
        domain: Option<&TrainingDomain>,
        pair: &LabeledPair,
    ) -> Self {
        let Some(domain) = domain else {
            return Self::UnknownAccuracy;
        };
        let departures = domain.departures(pair);
        if !departures.is_empty() {
            return Self::OutsideTraining(departures);
        }
        let Some(range_n) = estimate.magnitude_range_n() else {
            return Self::UnknownAccuracy;
        };
        let (low, high) = (BandPosition::of(range_n.0), BandPosition::of(range_n.1));
        if low == high {
            Self::Clear {
                position: low,
                range_n,
            }
        } else {
            Self::Unclear { range_n }
        }
    }

    /// How far to trust the estimate, in plain words: the line beside the number, for a reader
    /// who does not know the project's terms (the details are one click away).
    pub fn trust(&self) -> &'static str {
        match self {
            Self::Clear { .. } => {
                "How far to trust this: on images like the ones these weights learned from, \
                 the true force lay within each axis's range about 9 times in 10 when it was \
                 measured. A guide, not a measurement."
            }
            Self::Unclear { .. } => {
                "How far to trust this: the range shown crosses an edge of the band, so it cannot \
                 say on which side the force is."
            }
            Self::UnknownAccuracy => {
                "How far to trust this: not known. These weights carry no measured error."
            }
            Self::OutsideTraining(_) => {
                "How far to trust this: little. These images differ from the ones the weights \
                 learned from, and nothing here has measured how far off they are on them."
            }
        }
    }

    /// The sentence shown under the gauge, for `estimate`.
    pub fn text(&self, estimate: &TipForceEstimate) -> String {
        let m = estimate.force_n.magnitude();
        let range = |(low, high): (f32, f32)| {
            format!("|F| = {m:.3} N, {low:.3}–{high:.3} N within its 90 % intervals")
        };
        match self {
            Self::Clear { position, range_n } => {
                format!("{}: {}", range(*range_n), position.phrase())
            }
            Self::Unclear { range_n } => format!(
                "{}: too uncertain to place against the 0.1–0.3 N ablation band (the range spans \
                 an edge of the band)",
                range(*range_n)
            ),
            Self::UnknownAccuracy => format!(
                "|F| = {m:.3} N: no verdict against the 0.1–0.3 N ablation band (the accuracy \
                 of these weights is not known: their file records no measured error)"
            ),
            Self::OutsideTraining(departures) => format!(
                "|F| = {m:.3} N: no verdict: this pair lies outside what the weights were \
                 trained on ({}), so the estimate may be far off",
                departures.join("; ")
            ),
        }
    }
}

/// Root-mean-square length of the physics estimate's error vector on twin pairs read blind from
/// their exact masks, newtons: 0.032 N over 480 fresh bench pairs (R² 0.97; `hnet eval` on
/// `data/xray2-bench-224-s33`, the check from true masks). The figure before the page read twin
/// pairs blind, 0.013 N, was measured with each pair's own catheter and exact base, on 30 pairs
/// of the twin tab.
pub const PHYSICS_FORCE_ERROR_N: f32 = 0.032;

/// The physics estimate's per-axis mean square errors (x, y, z), N², read blind with the rod
/// fitted to the bundled weights' own masks rather than exact ones: 0.00184, 0.00161 and
/// 0.00370 over all 480 fresh bench pairs (`hnet eval` on `data/xray2-bench-224-s33`,
/// 2026-12-06; docs/results.md, "Force without the twin's answers"; the fit holds the force to
/// pushing, `hnet_twin::reconstruction::rod_fit::RodFitSettings::pushing_only`). This is how
/// the page reads a pair without label masks, or any pair with the rod fitted to H-Net's masks.
pub const PHYSICS_FORCE_MSE_FROM_HNET_MASKS_N2: [f32; 3] = [0.00184, 0.00161, 0.00370];

/// H-Net's and the physics estimate are said to disagree when their difference |ΔF| exceeds
/// this, newtons. If both err as measured, independently and normally (H-Net: the bundled
/// weights' per-axis mean square errors 0.00473, 0.00495 and 0.00371 N² on fresh bench pairs,
/// assets/MODEL.md; the blind physics estimate fitted to H-Net's own masks:
/// [`PHYSICS_FORCE_MSE_FROM_HNET_MASKS_N2`]), |ΔF| stays below 0.24 N on 96.1 % of pairs; from
/// exact masks ([`PHYSICS_FORCE_ERROR_N`]) on 99.2 % (the test below integrates both; `cargo
/// test -p hnet-studio --lib the_tolerance -- --nocapture` prints them). Beyond 0.24 N, one of
/// the two is off by more than its usual error. H-Net's coarse force and the blind fit's Fz
/// dominate it (the stage-4 weights' coarser masks needed 0.27 N).
pub const DISAGREEMENT_TOLERANCE_N: f32 = 0.24;

/// How far H-Net's estimate and the physics estimate are apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disagreement {
    /// |ΔF|, newtons.
    pub delta_n: f32,
}

impl Disagreement {
    /// Between H-Net's estimate `hnet_n` and the physics estimate `physics_n`.
    pub fn between(hnet_n: TipForce, physics_n: TipForce) -> Self {
        Self {
            delta_n: (hnet_n - physics_n).magnitude(),
        }
    }

    /// Whether it exceeds [`DISAGREEMENT_TOLERANCE_N`].
    pub fn beyond_tolerance(&self) -> bool {
        self.delta_n > DISAGREEMENT_TOLERANCE_N
    }

    /// The sentence shown under the force table.
    pub fn text(&self) -> String {
        let delta = self.delta_n;
        let tolerance = DISAGREEMENT_TOLERANCE_N;
        if self.beyond_tolerance() {
            format!(
                "H-Net and the physics estimate disagree: |ΔF| = {delta:.3} N, beyond the \
                 {tolerance:.2} N their measured errors explain on 95 % of twin pairs. One of \
                 them is off: check the masks the rod was fitted to, the catheter's settings and \
                 the C-arm angles."
            )
        } else {
            format!(
                "H-Net and the physics estimate agree within {tolerance:.2} N: |ΔF| = {delta:.3} N."
            )
        }
    }
}

#[cfg(all(test, not(target_arch = "wasm32")))]
pub(crate) mod tests {
    use super::*;
    use crate::twin_live::{TwinControls, XrayBackground};
    use hnet_twin::reconstruction::physics_force::EstimateKind;

    fn twin(controls: TwinControls) -> LabeledPair {
        controls
            .render("t".into(), &XrayBackground::phantom())
            .unwrap()
    }

    /// Weights whose facts are the bundled ones' (assets/MODEL.md: their force head's and
    /// combined estimate's errors on 480 fresh bench pairs, the combination calibrated on 598
    /// pairs of their training data's val split, trained on XRay-2 bench scenes on the phantom).
    pub(crate) fn bench_domain() -> TrainingDomain {
        TrainingDomain {
            domain: ForceDomain {
                data: "xray2-bench-224-s7".into(),
                modality: Modality::Xray2,
                scenes: hnet_twin::simulator::scene::SceneSampling::bench(),
                views_deg: [[0.0, 0.0], [90.0, 0.0]],
                phantom_backgrounds: true,
            },
            combination: ForceCombination {
                network_error_n: [0.0740, 0.0748, 0.0689],
                physics_sd_scale: 2.154,
                pairs: 598,
                interval_90_sd: [2.129, 2.189, 1.924],
                network_interval_90_n: None,
                stack: None,
            },
            head_error_n: 0.117,
            combined_error_n: Some(0.081),
        }
    }

    #[test]
    fn a_verdict_never_claims_more_than_the_intervals_allow() {
        let domain = bench_domain();
        let pair = twin(TwinControls::default());
        assert_eq!(domain.departures(&pair), Vec::<String>::new());
        // H-Net's 0.18 N with its own intervals (about ±0.12 N per axis) spans the band's lower
        // edge: no verdict.
        let head = domain.estimate(TipForce::new(0.18, 0.0, 0.0), None);
        assert_eq!(head.kind, EstimateKind::Head);
        let unclear = Verdict::of(&head, Some(&domain), &pair);
        assert!(matches!(unclear, Verdict::Unclear { .. }), "{unclear:?}");
        assert!(unclear.text(&head).contains("too uncertain"));
        // Precise weights may place it.
        let precise = TrainingDomain {
            combination: ForceCombination {
                network_interval_90_n: Some([0.01; 3]),
                ..domain.combination
            },
            ..domain.clone()
        };
        let sharp = precise.estimate(TipForce::new(0.18, 0.0, 0.0), None);
        assert_eq!(
            Verdict::of(&sharp, Some(&precise), &pair).text(&sharp),
            "|F| = 0.180 N, 0.170–0.191 N within its 90 % intervals: within the 0.1–0.3 N \
             ablation band"
        );
        assert_eq!(Verdict::of(&head, None, &pair), Verdict::UnknownAccuracy);
        let uncalibrated = TipForceEstimate::uncalibrated(TipForce::new(0.18, 0.0, 0.0));
        assert_eq!(
            Verdict::of(&uncalibrated, Some(&domain), &pair),
            Verdict::UnknownAccuracy
        );
        // The combined estimate, with a physics estimate that says much, places 0.20 N where
        // H-Net's intervals cannot.
        assert!(matches!(
            Verdict::of(
                &domain.estimate(TipForce::new(0.2, 0.0, 0.0), None),
                Some(&domain),
                &pair
            ),
            Verdict::Unclear { .. }
        ));
        let combined = domain.estimate(
            TipForce::new(0.2, 0.0, 0.0),
            Some((TipForce::new(0.2, 0.0, 0.0), Some([0.005; 3]))),
        );
        assert_eq!(combined.kind, EstimateKind::Combined);
        assert!(matches!(
            Verdict::of(&combined, Some(&domain), &pair),
            Verdict::Clear {
                position: BandPosition::Within,
                ..
            }
        ));
    }

    #[test]
    fn weights_without_recorded_facts_have_no_domain() {
        assert_eq!(TrainingDomain::of_facts(&ModelFacts::default()), None);
    }

    #[test]
    fn twin_settings_outside_the_training_data_get_no_verdict() {
        let domain = bench_domain();
        // The case: |F| 0.69 N pushing cranially (Fz > 0).
        let pair = twin(TwinControls {
            force_n: TipForce::new(0.4, 0.4, 0.4),
            view_a_deg: [30.0, 0.0],
            ..TwinControls::default()
        });
        let estimate = domain.estimate(TipForce::new(0.1, 0.1, 0.1), None);
        let verdict = Verdict::of(&estimate, Some(&domain), &pair);
        let Verdict::OutsideTraining(departures) = &verdict else {
            panic!("{verdict:?}");
        };
        assert!(departures[0].starts_with("|F| 0.69 N"), "{departures:?}");
        assert!(departures.iter().any(|d| d.starts_with("the force points")));
        assert!(
            departures
                .iter()
                .any(|d| d.starts_with("view A at +30°/+0°"))
        );
        assert!(verdict.text(&estimate).contains("no verdict"));
        // View A turned 30°: the head's force alone is withheld there, saying why; combined
        // with a physics estimate it stands. At the trained angles the head alone stands.
        let head = TipForce::new(0.1, 0.1, 0.1);
        let why = domain.estimate_at(head, None, &pair).unwrap_err();
        assert!(
            why.contains("view A at +30°/+0° (trained at +0°/+0°)"),
            "{why}"
        );
        let physics = Some((TipForce::new(0.2, 0.1, 0.0), Some([0.01; 3])));
        assert_eq!(
            domain.estimate_at(head, physics, &pair),
            Ok(domain.estimate(head, physics))
        );
        let at_trained_angles = twin(TwinControls::default());
        assert_eq!(
            domain.head_departures(&at_trained_angles),
            Vec::<String>::new()
        );
        assert_eq!(
            domain.estimate_at(head, None, &at_trained_angles),
            Ok(estimate)
        );
        // Another catheter at the trained angles: withheld too (the `varied` scenes' head R² was
        // below zero). A force outside the trained range is no reason: it is what is estimated.
        let stiffer = twin(TwinControls {
            stiffness_mn_m2: 0.9,
            ..TwinControls::default()
        });
        let why = domain.estimate_at(head, None, &stiffer).unwrap_err();
        assert!(why.contains("stiffness EI 0.90 mN·m²"), "{why}");
        let strong = twin(TwinControls {
            force_n: TipForce::new(0.0, 0.0, -1.5),
            ..TwinControls::default()
        });
        assert_eq!(domain.head_departures(&strong), Vec::<String>::new());
        assert!(!domain.departures(&strong).is_empty());
        // Beside it, how far to trust it in plain words: none of the project's own terms.
        for v in [
            verdict.clone(),
            Verdict::UnknownAccuracy,
            Verdict::Unclear {
                range_n: (0.05, 0.2),
            },
            Verdict::Clear {
                position: BandPosition::of(0.2),
                range_n: (0.15, 0.25),
            },
        ] {
            let trust = v.trust();
            assert!(trust.starts_with("How far to trust this: "), "{trust}");
            for jargon in ["R²", "IoU", "xray", "rod", "RMSE", "interval"] {
                assert!(!trust.contains(jargon), "{trust}");
            }
        }

        let rgb = twin(TwinControls {
            modality: Modality::Rgb,
            ..TwinControls::default()
        });
        let departures = domain.departures(&rgb);
        assert!(departures[0].starts_with("rgb images"), "{departures:?}");
    }

    #[test]
    fn uploaded_images_get_no_verdict_from_twin_trained_weights() {
        let upload = LabeledPair::new(
            "u".into(),
            PairSource::Upload {
                view_a: "a.png".into(),
                view_b: "b.png".into(),
                views: None,
            },
            Vec::new(),
            Vec::new(),
        );
        let domain = bench_domain();
        let estimate = domain.estimate(TipForce::new(0.5, 0.0, 0.0), None);
        // Read with the default biplane, the trained one: the head alone is shown (with no
        // verdict); stated at other angles, it is withheld.
        assert_eq!(domain.head_departures(&upload), Vec::<String>::new());
        let mut stated = upload.clone();
        stated.source = PairSource::Upload {
            view_a: "a.png".into(),
            view_b: "b.png".into(),
            views: Some(
                TwinControls {
                    view_b_deg: [60.0, 10.0],
                    ..TwinControls::default()
                }
                .views(),
            ),
        };
        assert_eq!(
            domain.head_departures(&stated),
            vec!["view B at +60°/+10° (trained at +90°/+0°)".to_string()]
        );
        let verdict = Verdict::of(&estimate, Some(&domain), &upload);
        assert!(
            verdict
                .text(&estimate)
                .contains("images that are not the twin's"),
            "{verdict:?}"
        );
    }

    /// The tolerance is the 95th percentile of |ΔF| when both estimates err as documented
    /// ([`DISAGREEMENT_TOLERANCE_N`]): independent normal errors per axis, integrated on a grid.
    #[test]
    fn the_tolerance_is_what_the_measured_errors_explain() {
        // The bundled weights' per-axis mean square errors, N² (assets/MODEL.md), whose root
        // sum is the domain's error.
        let hnet = [0.00473f64, 0.00495, 0.00371];
        let within = |tolerance: f64, physics: [f64; 3]| {
            let sd: Vec<f64> = (0..3).map(|i| (hnet[i] + physics[i]).sqrt()).collect();
            let steps = 90;
            let grid = |sd: f64| -> Vec<(f64, f64)> {
                let h = 10.0 * sd / steps as f64;
                (0..steps)
                    .map(|k| {
                        let x = -5.0 * sd + (k as f64 + 0.5) * h;
                        let density = (-0.5 * (x / sd).powi(2)).exp()
                            / (sd * (2.0 * std::f64::consts::PI).sqrt());
                        (x, density * h)
                    })
                    .collect()
            };
            let (gx, gy, gz) = (grid(sd[0]), grid(sd[1]), grid(sd[2]));
            let mut p = 0.0;
            for &(x, wx) in &gx {
                for &(y, wy) in &gy {
                    for &(z, wz) in &gz {
                        if x * x + y * y + z * z <= tolerance * tolerance {
                            p += wx * wy * wz;
                        }
                    }
                }
            }
            p
        };
        let from_hnet_masks = PHYSICS_FORCE_MSE_FROM_HNET_MASKS_N2.map(f64::from);
        let p = within(f64::from(DISAGREEMENT_TOLERANCE_N), from_hnet_masks);
        eprintln!("P(|ΔF| ≤ tolerance): {p:.4} from H-Net's masks");
        assert!((0.94..=0.97).contains(&p), "{p}");
        let exact = [f64::from(PHYSICS_FORCE_ERROR_N).powi(2) / 3.0; 3];
        let p = within(f64::from(DISAGREEMENT_TOLERANCE_N), exact);
        eprintln!("P(|ΔF| ≤ tolerance): {p:.4} from exact masks");
        assert!((0.99..=1.0).contains(&p), "{p}");
    }

    #[test]
    fn a_disagreement_beyond_the_tolerance_is_a_warning() {
        let agree =
            Disagreement::between(TipForce::new(0.1, 0.0, -0.1), TipForce::new(0.2, 0.0, -0.1));
        assert!((agree.delta_n - 0.1).abs() < 1e-6);
        assert!(!agree.beyond_tolerance());
        assert_eq!(
            agree.text(),
            "H-Net and the physics estimate agree within 0.24 N: |ΔF| = 0.100 N."
        );
        let apart = Disagreement::between(
            TipForce::new(0.1, 0.0, -0.1),
            TipForce::new(-0.1, 0.2, -0.1),
        );
        assert!(apart.beyond_tolerance());
        assert!(
            apart
                .text()
                .starts_with("H-Net and the physics estimate disagree: |ΔF| = 0.283 N, beyond"),
            "{}",
            apart.text()
        );
    }

    #[test]
    fn a_pair_without_a_catheter_gets_no_force() {
        let size = ImageSize::square(64);
        let empty = vec![0.0f32; size.pixels()];
        // A straight vertical catheter 4 pixels wide from the bottom edge up to mid-height.
        let tube: Vec<f32> = (0..size.pixels())
            .map(|i| {
                let (x, y) = (i % size.width, i / size.width);
                if (30..34).contains(&x) && y >= size.height / 2 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        assert_eq!(no_catheter_found(&tube, &tube, size), None);
        let why = no_catheter_found(&tube, &empty, size).unwrap();
        assert!(why.contains("view B: no catheter found"), "{why}");
        // A view painted catheter all over (the network does so to a black image).
        let everywhere = vec![1.0f32; size.pixels()];
        let why = no_catheter_found(&everywhere, &tube, size).unwrap();
        assert!(why.contains("more than a catheter covers"), "{why}");
    }

    #[test]
    fn band_positions() {
        assert_eq!(BandPosition::of(0.05), BandPosition::Below);
        assert_eq!(BandPosition::of(0.2), BandPosition::Within);
        assert_eq!(BandPosition::of(0.31), BandPosition::Above);
    }
}
