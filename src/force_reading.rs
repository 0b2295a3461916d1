//! What a tip-force estimate can be said to show: its magnitude against the ablation band, no more
//! than the weights' accuracy supports, and nothing at all for a twin pair outside the data the
//! weights were trained on; and whether H-Net's estimate and the physics estimate (the rod fitted
//! to the catheter in 3D, [`crate::catheter_3d`]) disagree beyond what their errors explain.

use hnet_twin::carm::Biplane;
use hnet_twin::centreline::{CentrelineSettings, Mask, catheter_seen};
use hnet_twin::physics_force::ForceCombination;
use hnet_twin::scene::{Modality, SceneParams, SceneSampling};

use crate::workspace::{LabeledPair, PairSource};
use hnet_units::force_magnitude as magnitude;

/// Why no force is read from a pair whose masks (catheter probabilities of views A and B, `side`
/// pixels square) do not both show a catheter ([`catheter_seen`]: enough catheter pixels, and
/// not too many, in one blob long enough for a catheter); `None` when both do. The same rule as `hnet study no-catheter` measures.
pub fn no_catheter_found(mask_a: &[f32], mask_b: &[f32], side: usize) -> Option<String> {
    let settings = CentrelineSettings::default();
    [(mask_a, "A"), (mask_b, "B")]
        .into_iter()
        .find_map(|(mask, view)| {
            catheter_seen(&Mask::soft(side, side, mask), view, &settings).err()
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

/// Which of the page's tip-force estimates a verdict reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimator {
    /// H-Net's force head.
    Hnet,
    /// H-Net's force combined with the physics estimate from H-Net's own masks
    /// ([`TrainingDomain::force_combination`]).
    Combined,
}

impl Estimator {
    /// Its name on the page (the force table's row).
    pub fn name(self) -> &'static str {
        match self {
            Self::Hnet => "H-Net",
            Self::Combined => "Combined",
        }
    }
}

/// What a set of weights was trained on, and how far its force estimates are off there.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingDomain {
    /// Root-mean-square length of the force error vector on held-out pairs, newtons: a bound on
    /// the RMS error of the estimated magnitude |F|.
    pub force_error_n: f32,
    /// How these weights' force and the physics estimate from their masks are combined: each
    /// one's error, measured on calibration pairs.
    pub force_combination: ForceCombination,
    /// [`Self::force_error_n`] of that combined estimate, newtons.
    pub combined_force_error_n: f32,
    /// The images' look.
    pub modality: Modality,
    /// How the training scenes were drawn.
    pub scenes: SceneSampling,
    /// Each view's C-arm angles (primary, secondary), degrees.
    pub views_deg: [[f64; 2]; 2],
    /// Whether every X-ray background was cut from the built-in thorax phantom.
    pub phantom_backgrounds: bool,
}

/// The bundled weights' force head's per-axis mean square errors (x, y, z), N², on 480 fresh
/// bench pairs (`hnet eval` on `data/xray2-bench-224-s33`, assets/MODEL.md).
pub const BUNDLED_FORCE_MSE_N2: [f32; 3] = [0.00480, 0.00514, 0.00370];

/// Their combined estimate's ([`TrainingDomain::force_combination`]) on the 475 of those pairs
/// read blind whose masks gave a physics estimate, N² (docs/results.md, "Force without the
/// twin's answers"; `hnet eval --weights assets/hnet-cpu.bpk --data data/xray2-bench-224-s33
/// --split train --calibration data/xray2-bench-224-s7`).
pub const BUNDLED_COMBINED_FORCE_MSE_N2: [f32; 3] = [0.00205, 0.00203, 0.00244];

/// The root-mean-square length of an error vector whose per-axis mean square errors are
/// `mse_n2` (N²), newtons: a bound on the RMS error of the magnitude |F|.
fn error_length_n(mse_n2: [f32; 3]) -> f32 {
    mse_n2.iter().sum::<f32>().sqrt()
}

impl TrainingDomain {
    /// The bundled weights (`assets/MODEL.md`): their force was trained on XRay-2 bench scenes
    /// on phantom backgrounds, the default biplane (0°/0° and 90°/0°); other catheters, poses,
    /// angles and radiograph backgrounds taught their masks only. Their force error is √(ΣMSE)
    /// of [`BUNDLED_FORCE_MSE_N2`], 0.117 N; their combined estimate's, read blind, of
    /// [`BUNDLED_COMBINED_FORCE_MSE_N2`], 0.081 N. Their combination with the blind physics
    /// estimate was calibrated on the 598 fitted pairs of the val split of their training data
    /// (`hnet eval --weights assets/hnet-cpu.bpk --data data/xray2-bench-224-s7`, blind, the
    /// default; its 90 % intervals covered 89 / 90 / 92 % of the 475 of 480 fresh bench pairs that
    /// got a physics estimate).
    pub fn bundled() -> Self {
        Self {
            force_error_n: error_length_n(BUNDLED_FORCE_MSE_N2),
            combined_force_error_n: error_length_n(BUNDLED_COMBINED_FORCE_MSE_N2),
            force_combination: ForceCombination {
                network_error_n: [0.0740, 0.0748, 0.0689],
                physics_sd_scale: 2.154,
                pairs: 598,
                interval_90_sd: [2.129, 2.189, 1.924],
            },
            modality: Modality::Xray2,
            scenes: SceneSampling::bench(),
            views_deg: [[0.0, 0.0], [90.0, 0.0]],
            phantom_backgrounds: true,
        }
    }

    /// The force error of `estimator`'s estimates, newtons.
    pub fn force_error_of(&self, estimator: Estimator) -> f32 {
        match estimator {
            Estimator::Hnet => self.force_error_n,
            Estimator::Combined => self.combined_force_error_n,
        }
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
                self.modality.name()
            )
        };
        let (views, settings) = match &pair.source {
            PairSource::Twin {
                views, settings, ..
            } => (views, settings),
            PairSource::Dicom { views, .. } => {
                let mut departures = vec![not_twin()];
                departures.extend(self.view_departures(views));
                return departures;
            }
            PairSource::Upload { .. } => return vec![not_twin()],
        };
        let mut departures = Vec::new();
        let Some(modality) = settings["modality"].as_str().and_then(Modality::parse) else {
            return vec!["the pair's twin settings cannot be read".into()];
        };
        if modality != self.modality {
            departures.push(format!(
                "{} images (trained on {} only)",
                modality.name(),
                self.modality.name()
            ));
        }
        match serde_json::from_value::<SceneParams>(settings["scene"].clone()) {
            Ok(scene) => departures.extend(self.scenes.departures(&scene)),
            Err(_) => departures.push("the pair's twin settings cannot be read".into()),
        }
        departures.extend(self.view_departures(views));
        let source = settings["background"]["source"].as_str();
        if self.phantom_backgrounds
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

    /// The views whose C-arm angles differ from the trained ones by more than half a degree.
    fn view_departures(&self, views: &Biplane) -> Vec<String> {
        let mut departures = Vec::new();
        for (letter, (view, trained)) in ["A", "B"]
            .iter()
            .zip([views.a, views.b].iter().zip(self.views_deg))
        {
            let angles = [view.primary_deg, view.secondary_deg];
            if (angles[0] - trained[0]).abs() > 0.5 || (angles[1] - trained[1]).abs() > 0.5 {
                departures.push(format!(
                    "view {letter} at {:+.0}°/{:+.0}° (trained at {:+.0}°/{:+.0}°)",
                    angles[0], angles[1], trained[0], trained[1]
                ));
            }
        }
        departures
    }
}

/// What the page says about an estimated magnitude.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// The estimate and its error lie on one side of the band's edges.
    Clear {
        /// Where.
        position: BandPosition,
        /// The force error of the estimate read (the weights', or their combined estimate's), N.
        error_n: f32,
    },
    /// Within its error, the estimate could lie on either side of an edge of the band.
    Unclear {
        /// The force error of the estimate read (the weights', or their combined estimate's), N.
        error_n: f32,
    },
    /// Weights whose accuracy is not known (loaded by the user, or untrained).
    UnknownAccuracy,
    /// A pair outside what the weights were trained on (uploads included).
    OutsideTraining(Vec<String>),
}

impl Verdict {
    /// The verdict on `estimator`'s estimate `force_n` of `pair` from weights trained on
    /// `domain` (`None`: unknown weights).
    pub fn of(
        force_n: [f32; 3],
        estimator: Estimator,
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
        let m = magnitude(force_n);
        let error_n = domain.force_error_of(estimator);
        let (low, high) = (BandPosition::of(m - error_n), BandPosition::of(m + error_n));
        if low == high {
            Self::Clear {
                position: low,
                error_n,
            }
        } else {
            Self::Unclear { error_n }
        }
    }

    /// The sentence shown under the gauge, for estimate `force_n`.
    pub fn text(&self, force_n: [f32; 3]) -> String {
        let m = magnitude(force_n);
        match self {
            Self::Clear { position, error_n } => {
                format!("|F| = {m:.3} ± {error_n:.3} N: {}", position.phrase())
            }
            Self::Unclear { error_n } => format!(
                "|F| = {m:.3} ± {error_n:.3} N: too uncertain to place against the 0.1–0.3 N \
                 ablation band (the error spans an edge of the band)"
            ),
            Self::UnknownAccuracy => format!(
                "|F| = {m:.3} N: no verdict against the 0.1–0.3 N ablation band (the accuracy \
                 of these weights is not known)"
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
/// fitted to the bundled weights' own masks rather than exact ones: 0.00400, 0.00307 and
/// 0.00631 over the 475 of 480 fresh bench pairs that gave one (`hnet eval` on
/// `data/xray2-bench-224-s33`, docs/results.md, "Force without the twin's answers"; the fit
/// holds the force to pushing, `hnet_twin::rod_fit::RodFitSettings::pushing_only`). This is how
/// the page reads a pair without label masks, or any pair with the rod fitted to H-Net's masks.
pub const PHYSICS_FORCE_MSE_FROM_HNET_MASKS_N2: [f32; 3] = [0.00400, 0.00307, 0.00631];

/// H-Net's and the physics estimate are said to disagree when their difference |ΔF| exceeds
/// this, newtons. If both err as measured, independently and normally (H-Net: the bundled
/// weights' [`BUNDLED_FORCE_MSE_N2`]; the blind physics estimate fitted to H-Net's own masks:
/// [`PHYSICS_FORCE_MSE_FROM_HNET_MASKS_N2`]), |ΔF| stays below 0.27 N on 95.6 % of pairs; from
/// exact masks ([`PHYSICS_FORCE_ERROR_N`]) on 99.8 % (the test below integrates both; `cargo
/// test -p hnet-studio --lib the_tolerance -- --nocapture` prints them). Beyond 0.27 N, one of
/// the two is off by more than its usual error. H-Net's coarse force and the blind fit's Fz
/// dominate it (with the pair's own catheter and base it was 0.20 N).
pub const DISAGREEMENT_TOLERANCE_N: f32 = 0.27;

/// How far H-Net's estimate and the physics estimate are apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disagreement {
    /// |ΔF|, newtons.
    pub delta_n: f32,
}

impl Disagreement {
    /// Between H-Net's estimate `hnet_n` and the physics estimate `physics_n`.
    pub fn between(hnet_n: [f32; 3], physics_n: [f32; 3]) -> Self {
        Self {
            delta_n: magnitude([0, 1, 2].map(|i| hnet_n[i] - physics_n[i])),
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
mod tests {
    use super::*;
    use crate::twin_live::{TwinControls, XrayBackground};

    fn twin(controls: TwinControls) -> LabeledPair {
        controls
            .render("t".into(), &XrayBackground::phantom())
            .unwrap()
    }

    #[test]
    fn a_verdict_never_claims_more_than_the_error_allows() {
        let domain = TrainingDomain::bundled();
        let pair = twin(TwinControls::default());
        assert_eq!(domain.departures(&pair), Vec::<String>::new());
        // The errors the page states for the bundled weights.
        assert!((domain.force_error_n - 0.117).abs() < 5e-4);
        assert!((domain.combined_force_error_n - 0.081).abs() < 5e-4);
        // 0.18 N ± 0.117 N spans the band's lower edge: no verdict.
        let unclear = Verdict::of([0.18, 0.0, 0.0], Estimator::Hnet, Some(&domain), &pair);
        assert_eq!(
            unclear,
            Verdict::Unclear {
                error_n: domain.force_error_n
            }
        );
        assert!(unclear.text([0.18, 0.0, 0.0]).contains("too uncertain"));
        // Precise weights may place it.
        let precise = TrainingDomain {
            force_error_n: 0.01,
            ..domain.clone()
        };
        assert_eq!(
            Verdict::of([0.18, 0.0, 0.0], Estimator::Hnet, Some(&precise), &pair)
                .text([0.18, 0.0, 0.0]),
            "|F| = 0.180 ± 0.010 N: within the 0.1–0.3 N ablation band"
        );
        assert_eq!(
            Verdict::of([0.18, 0.0, 0.0], Estimator::Hnet, None, &pair),
            Verdict::UnknownAccuracy
        );
        // The combined estimate, 1.45 times closer, places a magnitude H-Net's error cannot:
        // 0.20 N (± 0.117 N spans the lower edge).
        assert_eq!(
            Verdict::of([0.2, 0.0, 0.0], Estimator::Hnet, Some(&domain), &pair),
            Verdict::Unclear {
                error_n: domain.force_error_n
            }
        );
        let combined = Verdict::of([0.2, 0.0, 0.0], Estimator::Combined, Some(&domain), &pair);
        assert_eq!(
            combined,
            Verdict::Clear {
                position: BandPosition::Within,
                error_n: domain.combined_force_error_n,
            }
        );
    }

    #[test]
    fn twin_settings_outside_the_training_data_get_no_verdict() {
        let domain = TrainingDomain::bundled();
        // The case: |F| 0.69 N pushing cranially (Fz > 0).
        let pair = twin(TwinControls {
            force_n: [0.4, 0.4, 0.4],
            view_a_deg: [30.0, 0.0],
            ..TwinControls::default()
        });
        let verdict = Verdict::of([0.1, 0.1, 0.1], Estimator::Hnet, Some(&domain), &pair);
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
        assert!(verdict.text([0.1, 0.1, 0.1]).contains("no verdict"));

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
            },
            Vec::new(),
            Vec::new(),
        );
        let verdict = Verdict::of(
            [0.5, 0.0, 0.0],
            Estimator::Combined,
            Some(&TrainingDomain::bundled()),
            &upload,
        );
        assert!(
            verdict
                .text([0.5, 0.0, 0.0])
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
        let hnet = BUNDLED_FORCE_MSE_N2.map(f64::from);
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
        assert!((0.94..=0.96).contains(&p), "{p}");
        let exact = [f64::from(PHYSICS_FORCE_ERROR_N).powi(2) / 3.0; 3];
        let p = within(f64::from(DISAGREEMENT_TOLERANCE_N), exact);
        eprintln!("P(|ΔF| ≤ tolerance): {p:.4} from exact masks");
        assert!((0.99..=1.0).contains(&p), "{p}");
    }

    #[test]
    fn a_disagreement_beyond_the_tolerance_is_a_warning() {
        let agree = Disagreement::between([0.1, 0.0, -0.1], [0.2, 0.0, -0.1]);
        assert!((agree.delta_n - 0.1).abs() < 1e-6);
        assert!(!agree.beyond_tolerance());
        assert_eq!(
            agree.text(),
            "H-Net and the physics estimate agree within 0.27 N: |ΔF| = 0.100 N."
        );
        let apart = Disagreement::between([0.1, 0.0, -0.1], [-0.1, 0.2, -0.1]);
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
        let side = 64;
        let empty = vec![0.0f32; side * side];
        // A straight vertical catheter 4 pixels wide from the bottom edge up to mid-height.
        let tube: Vec<f32> = (0..side * side)
            .map(|i| {
                let (x, y) = (i % side, i / side);
                if (30..34).contains(&x) && y >= side / 2 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        assert_eq!(no_catheter_found(&tube, &tube, side), None);
        let why = no_catheter_found(&tube, &empty, side).unwrap();
        assert!(why.contains("view B: no catheter found"), "{why}");
        // A view painted catheter all over (the network does so to a black image).
        let everywhere = vec![1.0f32; side * side];
        let why = no_catheter_found(&everywhere, &tube, side).unwrap();
        assert!(why.contains("more than a catheter covers"), "{why}");
    }

    #[test]
    fn band_positions() {
        assert_eq!(BandPosition::of(0.05), BandPosition::Below);
        assert_eq!(BandPosition::of(0.2), BandPosition::Within);
        assert_eq!(BandPosition::of(0.31), BandPosition::Above);
    }
}
