//! The catheter in 3D and its physics-checked tip force, for the pair on screen: each view's mask
//! gives a centreline ([`hnet_twin::reconstruction::centreline`]), the two are matched along epipolar lines and
//! triangulated ([`hnet_twin::reconstruction::epipolar`]), and the twin's Kirchhoff rod is fitted to the
//! result ([`hnet_twin::reconstruction::rod_fit`]); its tip force is the physics estimate shown beside H-Net's.
//!
//! Where the numbers come from:
//!
//! - **Views.** A twin pair carries the C-arms it was rendered with (at
//!   [`crate::imaging::WORK_SIZE`]); an uploaded pair is read with the page's default views, the
//!   biplane the twin tab starts with (frontal and left lateral), as its force arrows are.
//! - **Catheter.** A twin pair is read blind, as `hnet eval` reads one by default: the
//!   catalogue's bench catheter (not the pair's own stiffness, length and pre-curve) and the
//!   bench fixture's nominal base, whose position and orientation are fitted with the force
//!   within the fixture's tolerance ([`PhysicsSetup::blind`]); nothing of the pair's own record.
//!   For an uploaded pair or a DICOM frame, the catheter set on the twin tab's sliders, clamped
//!   at the twin's nominal base, whose position and orientation are then fitted too (a real
//!   pair's base is not known exactly).
//! - **Masks.** The label masks when the pair has them (the twin's exact masks, H-Net's masks
//!   accepted as labels, or the user's strokes), else H-Net's predicted masks (soft, as they come
//!   out of the network); or H-Net's masks also where there are labels, when the user asks
//!   ([`FitMasks`]).
//!
//! Every way this can fail is a [`Catheter3dError`] naming the step and keeping the cause; the
//! page shows it in the 3D panel and nothing else changes. Browser-free: it builds and is tested
//! natively (about 20 ms per pair there).
//!
//! The 3D drawing's own geometry is here too ([`CArmSketch`], [`force_arrow_mm`]); its camera is
//! [`crate::orbit_camera`].

use hnet_twin::reconstruction::MaskOrigin;
use hnet_twin::reconstruction::catalogue::{
    BENCH_CATHETER, CatalogueCatheter, StiffnessCalibration, catalogue,
};
use hnet_twin::reconstruction::centreline::{CentrelineError, Mask};
use hnet_twin::reconstruction::epipolar::{EpipolarGeometry, ReconstructionError, clip_line};
use hnet_twin::reconstruction::physics_force::{
    MAX_FIT_RMS_MM, PhysicsError, PhysicsEstimate, PhysicsSetup, TipUse, physics_estimate,
};
use hnet_twin::reconstruction::rod_fit::RodFitError;
use hnet_twin::simulator::carm::{Biplane, CArm, CameraMatrix};
use hnet_twin::simulator::rod::{RodBase, RodConfig};
use hnet_twin::simulator::scene::{NominalBase, SceneParams, SceneSampling};
use hnet_units::TipForce;

use crate::imaging::WORK_SIZE;
use crate::twin_live::TwinControls;
use crate::workspace::{LabeledPair, PairSource, View};

/// Which masks the user asked the rod to be fitted to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FitMasks {
    /// The label masks when the pair has them, else H-Net's.
    #[default]
    LabelsFirst,
    /// H-Net's masks, also where the pair has labels (on a twin pair: the physics estimate as
    /// a real pair would get it, and the combined estimate the bundled weights are calibrated
    /// for).
    Hnet,
}

impl FitMasks {
    /// The value of its option in the page's choice.
    pub fn value(self) -> &'static str {
        match self {
            Self::LabelsFirst => "labels",
            Self::Hnet => "hnet",
        }
    }

    /// The choice with option value `value`.
    pub fn from_value(value: &str) -> Option<Self> {
        [Self::LabelsFirst, Self::Hnet]
            .into_iter()
            .find(|c| c.value() == value)
    }
}

/// Both views' masks at [`WORK_SIZE`], as a reconstruction reads them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PairMasks<'a> {
    /// Label masks (0 background, 255 catheter).
    Labels([&'a [u8]; 2]),
    /// H-Net's catheter probabilities in `[0, 1]`.
    Predicted([&'a [f32]; 2]),
}

impl<'a> PairMasks<'a> {
    /// The masks of `pair` to reconstruct from, as `choice` asks: its labels when it has them
    /// (unless `choice` asks for H-Net's), else `predicted` (H-Net's masks of view A and view
    /// B), else none.
    pub fn of(
        pair: &'a LabeledPair,
        predicted: Option<[&'a [f32]; 2]>,
        choice: FitMasks,
    ) -> Result<Self, Catheter3dError> {
        if pair.masks_labeled && choice == FitMasks::LabelsFirst {
            Ok(Self::Labels([pair.mask(View::A), pair.mask(View::B)]))
        } else {
            predicted.map(Self::Predicted).ok_or(match choice {
                FitMasks::Hnet => Catheter3dError::NoPredictedMasks,
                FitMasks::LabelsFirst => Catheter3dError::NoMasks,
            })
        }
    }

    /// Where they came from.
    pub fn source(&self) -> MaskOrigin {
        match self {
            Self::Labels(_) => MaskOrigin::Labels,
            Self::Predicted(_) => MaskOrigin::Predicted,
        }
    }

    fn mask(&self, index: usize) -> Mask<'a> {
        match self {
            Self::Labels(m) => Mask::coverage8(WORK_SIZE.width, WORK_SIZE.height, m[index]),
            Self::Predicted(m) => Mask::soft(WORK_SIZE.width, WORK_SIZE.height, m[index]),
        }
    }
}

/// How the pair's two views see the world, and the catheter the rod model assumes.
#[derive(Debug, Clone, PartialEq)]
pub struct PairGeometry {
    /// View A's and view B's C-arms at [`WORK_SIZE`].
    pub views: Biplane,
    /// The catheter's flexible section.
    pub rod: RodConfig,
    /// Where it is clamped.
    pub base: RodBase,
    /// Whether the base pose is exact; if not, the fit moves and turns it.
    pub base_known: bool,
    /// The catalogue catheter and nominal base a blind reading assumes (twin pairs), in place
    /// of [`Self::rod`] and [`Self::base`].
    pub blind: Option<(CatalogueCatheter, NominalBase)>,
    /// Whether the views are the page's default biplane, assumed for an uploaded pair rather
    /// than known: the reconstruction's reprojection error then only reflects that assumption.
    pub views_assumed: bool,
}

/// The views of `pair`: the twin's own, or the page's default biplane for an uploaded pair.
pub fn pair_views(pair: &LabeledPair) -> Biplane {
    match &pair.source {
        PairSource::Twin { views, .. } | PairSource::Dicom { views, .. } => *views,
        PairSource::Upload { views, .. } => views.unwrap_or_else(default_views),
    }
}

/// The preset a twin pair's `settings` were rendered with: the paper's bench when they say so,
/// else the twin's C-arm bench.
fn twin_preset(settings: &serde_json::Value) -> SceneSampling {
    settings["preset"]
        .as_str()
        .and_then(SceneSampling::preset)
        .unwrap_or_else(SceneSampling::bench)
}

/// The page's default views: the biplane the twin tab starts with, at [`WORK_SIZE`].
pub fn default_views() -> Biplane {
    TwinControls::default().views()
}

impl PairGeometry {
    /// The geometry of `pair`; `catheter` (the twin tab's sliders) sets the catheter of an
    /// uploaded pair or a DICOM frame (whose views come from its headers). A `calibration`
    /// ([`crate::catheter_calibration`]) scales the stiffness the page assumes: the catalogue
    /// catheter's for twin pairs, the sliders' for the others.
    pub fn of(
        pair: &LabeledPair,
        catheter: &TwinControls,
        calibration: Option<&StiffnessCalibration>,
    ) -> Result<Self, Catheter3dError> {
        let template = RodConfig::default();
        let scale = calibration.map_or(1.0, |c| c.scale);
        match &pair.source {
            PairSource::Twin {
                views, settings, ..
            } => {
                // The settings must still read (a record from another version is named), though
                // a blind reading uses none of them.
                let scene: SceneParams = serde_json::from_value(settings["scene"].clone())
                    .map_err(Catheter3dError::TwinSettings)?;
                let (rod, base) = scene.rod(&template);
                let mut catheter = catalogue()
                    .into_iter()
                    .find(|c| c.name == BENCH_CATHETER)
                    .expect("the bench catheter is in the catalogue");
                catheter.bending_stiffness_n_m2 *= scale;
                Ok(Self {
                    views: *views,
                    rod,
                    base,
                    base_known: false,
                    blind: Some((catheter, twin_preset(settings).nominal_base())),
                    views_assumed: false,
                })
            }
            PairSource::Upload { .. } | PairSource::Dicom { .. } => {
                let mut scene = catheter.scene();
                scene.bending_stiffness_n_m2 *= scale;
                let (rod, base) = scene.rod(&template);
                Ok(Self {
                    views: pair_views(pair),
                    rod,
                    base,
                    base_known: false,
                    blind: None,
                    views_assumed: matches!(pair.source, PairSource::Upload { views: None, .. }),
                })
            }
        }
    }

    /// Both views' camera matrices.
    pub fn cameras(&self) -> [CameraMatrix; 2] {
        [self.views.a.camera_matrix(), self.views.b.camera_matrix()]
    }
}

/// The epipolar line in view `to` of the point `at` (image pixels) of the other view, clipped
/// to the image: its two end points in `to`'s pixels. `None` when the cameras are unusable or
/// the line misses the image.
pub fn epipolar_line(views: &Biplane, to: View, at: [f64; 2]) -> Option<[[f64; 2]; 2]> {
    let geometry =
        EpipolarGeometry::new(&views.a.camera_matrix(), &views.b.camera_matrix()).ok()?;
    let line = match to {
        View::B => geometry.line_in_b(at),
        View::A => geometry.line_in_a(at),
    };
    let size = match to {
        View::A => views.a.image_size,
        View::B => views.b.image_size,
    };
    clip_line(line, size.width as f64, size.height as f64)
}

/// The reconstructed catheter and the rod fitted to it.
#[derive(Debug, Clone, PartialEq)]
pub struct Catheter3d {
    /// The masks it was made from.
    pub masks: MaskOrigin,
    /// The 3D centreline, mm (world frame), from where the catheter enters both images to its
    /// tip.
    pub centreline_mm: Vec<[f64; 3]>,
    /// Its length, mm.
    pub length_mm: f64,
    /// Mean reprojection error of its points, pixels.
    pub mean_residual_px: f64,
    /// Whether its last point is the tip, seen in both views.
    pub tip_seen: bool,
    /// What the rod fit made of that tip (a blind fit weighs it, or sets it aside where the
    /// catalogue's flexible length does not reach it).
    pub tip: TipUse,
    /// The physics estimate: the tip force of the fitted rod, N (world frame).
    pub force_n: TipForce,
    /// The fit's standard error of each force component, N (a relative measure until scaled by
    /// a [`ForceCombination`](hnet_twin::reconstruction::physics_force::ForceCombination)); `None` for a singular fit.
    pub force_sd_n: Option<[f32; 3]>,
    /// Root mean square distance of the centreline from the fitted rod, mm.
    pub rms_mm: f64,
    /// The fitted rod's centreline, mm, from its base to its tip.
    pub rod_mm: Vec<[f64; 3]>,
    /// Whether the base pose was fitted too.
    pub base_fitted: bool,
    /// The catalogue catheter a blind reading assumed (twin pairs).
    pub blind_catheter: Option<String>,
    /// Whether the views were assumed (the page's default biplane for an upload), so that the
    /// reprojection error checks nothing and is not shown.
    pub views_assumed: bool,
    /// Sizes in pixels of the blobs set aside beside the catheter in view A and in view B
    /// (another device, or the background read as catheter:
    /// [`hnet_twin::reconstruction::centreline`]).
    pub set_aside_px: [Vec<usize>; 2],
}

impl Catheter3d {
    /// This physics estimate (its force and its fit's standard error, N) as the combination
    /// with H-Net's force reads it ([`crate::force_reading::TrainingDomain::estimate`]), when the
    /// rod was fitted to H-Net's own masks, the case the combination is for (measured on twin
    /// bench pairs read blind: docs/results.md, "Force without the twin's answers"). From label
    /// masks there is none: from the twin's exact masks the physics estimate is far better than
    /// H-Net on every axis, and for drawn or accepted masks nothing was measured.
    pub fn for_combination(&self) -> Option<(TipForce, Option<[f32; 3]>)> {
        (self.masks == MaskOrigin::Predicted).then_some((self.force_n, self.force_sd_n))
    }

    /// The catheter's tip (the last centreline point), mm.
    pub fn tip_mm(&self) -> [f64; 3] {
        *self
            .centreline_mm
            .last()
            .expect("a reconstruction has points")
    }

    /// What was set aside beside the catheter, as the end of [`Catheter3d::summary`]'s
    /// sentence ("; view B: a blob of 120 px beside the catheter set aside"), or nothing.
    fn set_aside_phrase(&self) -> String {
        ["A", "B"]
            .iter()
            .zip(&self.set_aside_px)
            .filter(|(_, sizes)| !sizes.is_empty())
            .map(|(view, sizes)| {
                let list = sizes
                    .iter()
                    .map(|s| format!("{s} px"))
                    .collect::<Vec<_>>()
                    .join(", ");
                if sizes.len() == 1 {
                    format!("; view {view}: a blob of {list} beside the catheter set aside")
                } else {
                    format!("; view {view}: blobs of {list} beside the catheter set aside")
                }
            })
            .collect()
    }

    /// One sentence for screen readers and the panel.
    pub fn summary(&self) -> String {
        let f = self.force_n;
        let magnitude = f.magnitude();
        format!(
            "catheter {:.0} mm reconstructed from {} ({}, {}); physics force ({:+.3}, {:+.3}, \
             {:+.3}) N, |F| {magnitude:.3} N, from a rod fitted within {:.2} mm RMS{}{}",
            self.length_mm,
            self.masks.phrase(),
            match (self.tip_seen, self.tip) {
                (false, _) => "tip outside a view",
                (true, TipUse::SetAside) => {
                    "tip seen in both views, set aside by the fit: the catheter's flexible length \
                     does not reach it"
                }
                (true, _) => "tip seen in both views",
            },
            if self.views_assumed {
                "C-arms assumed at the page's default angles, not known: no reprojection check"
                    .to_string()
            } else {
                format!("{:.2} px mean reprojection error", self.mean_residual_px)
            },
            f[0],
            f[1],
            f[2],
            self.rms_mm,
            match (&self.blind_catheter, self.base_fitted) {
                (Some(name), _) => format!(
                    " (read blind: the catalogue's {name}, its base pose fitted near the bench \
                     fixture's)"
                ),
                (None, true) => " (its base pose fitted too)".to_string(),
                (None, false) => String::new(),
            },
            self.set_aside_phrase(),
        )
    }
}

/// Why the pair gives no 3D catheter.
#[derive(Debug, thiserror::Error)]
pub enum Catheter3dError {
    /// Neither label masks nor H-Net's masks.
    #[error("no masks to reconstruct from: label the catheter in both views, or run H-Net")]
    NoMasks,
    /// H-Net's masks were asked for, and H-Net has not run on the pair.
    #[error("the rod is to be fitted to H-Net's masks, and H-Net has not run on this pair yet")]
    NoPredictedMasks,
    /// A twin pair whose recorded settings cannot be read.
    #[error("the pair's twin settings cannot be read")]
    TwinSettings(#[source] serde_json::Error),
    /// A view's mask gives no centreline (empty, two blobs, not one tube, too short).
    #[error("no centreline in {}", .masks.phrase())]
    Centreline {
        /// The masks read.
        masks: MaskOrigin,
        /// Why.
        #[source]
        source: CentrelineError,
    },
    /// The centrelines cannot be matched in 3D (unusable cameras, no overlap, along the
    /// epipolar lines).
    #[error("the two views cannot be matched in 3D")]
    Reconstruction(#[source] ReconstructionError),
    /// No rod fits the reconstruction.
    #[error("no physics estimate")]
    Fit(#[source] RodFitError),
    /// The best rod stays far from the reconstruction: the catheter's settings, the views or the
    /// masks do not describe this catheter, and its force would mean nothing.
    #[error(
        "no physics estimate: the best-fitting rod stays {rms_mm:.2} mm RMS from the reconstructed \
         catheter (at most {MAX_FIT_RMS_MM} mm accepted); the catheter's settings, the C-arm \
         geometry or the masks do not match this pair"
    )]
    PoorFit {
        /// RMS distance of the reconstruction from the fitted rod, mm.
        rms_mm: f64,
    },
    /// The rod fits, but not as the catheter assumed could lie.
    #[error("no physics estimate")]
    Unreadable(#[source] PhysicsError),
}

/// Reconstructs the catheter of `masks` seen with `geometry` and fits the rod to it.
pub fn reconstruct_pair(
    geometry: &PairGeometry,
    masks: &PairMasks<'_>,
) -> Result<Catheter3d, Catheter3dError> {
    let setup = match &geometry.blind {
        Some((catheter, nominal)) => PhysicsSetup::blind(geometry.cameras(), catheter, nominal),
        None => {
            let mut setup =
                PhysicsSetup::new(geometry.cameras(), geometry.rod.clone(), geometry.base);
            setup.fit.fit_base_position = !geometry.base_known;
            setup.fit.fit_base_rotation = !geometry.base_known;
            setup.max_fit_rms_mm = Some(MAX_FIT_RMS_MM);
            setup
        }
    };
    let PhysicsEstimate {
        centrelines,
        reconstruction,
        fit,
        tip,
    } = physics_estimate([masks.mask(0), masks.mask(1)], &setup).map_err(|e| match e {
        PhysicsError::Centreline(source) => Catheter3dError::Centreline {
            masks: masks.source(),
            source,
        },
        PhysicsError::Reconstruction(e) => Catheter3dError::Reconstruction(e),
        PhysicsError::Fit(e) => Catheter3dError::Fit(e),
        PhysicsError::PoorFit { rms_mm, .. } => Catheter3dError::PoorFit { rms_mm },
        e @ (PhysicsError::BaseOutsideTolerance { .. }
        | PhysicsError::AtForceLimit { .. }
        | PhysicsError::RodBeyondSeenTip { .. }) => Catheter3dError::Unreadable(e),
    })?;
    Ok(Catheter3d {
        masks: masks.source(),
        centreline_mm: reconstruction.points_mm.iter().map(|p| p.0).collect(),
        length_mm: reconstruction.arc_mm.last().copied().unwrap_or(0.0),
        mean_residual_px: reconstruction.mean_residual_px,
        tip_seen: reconstruction.tip_seen,
        tip,
        force_n: fit.force_n,
        force_sd_n: fit.force_sd_n,
        rms_mm: fit.rms_mm,
        rod_mm: fit.shape.points_mm.iter().map(|p| p.0).collect(),
        base_fitted: !geometry.base_known,
        blind_catheter: geometry.blind.as_ref().map(|(c, _)| c.name.clone()),
        views_assumed: geometry.views_assumed,
        set_aside_px: centrelines.map(|c| c.set_aside_px),
    })
}

/// The C-arms are drawn at this fraction of their size about the isocentre, the catheter at full
/// size: a cardiac C-arm's source is 750 mm from the isocentre and its detector 450 mm beyond
/// it, against a catheter of about 50 mm, which would be a few pixels in a drawing of the whole.
/// Scaled about the isocentre, every direction and angle stays true.
pub const CARM_SKETCH_SCALE: f64 = 0.1;

/// What the 3D view draws of one C-arm, mm (world frame, scaled by [`CARM_SKETCH_SCALE`] about
/// the isocentre).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CArmSketch {
    /// The X-ray source (focal spot).
    pub source_mm: [f64; 3],
    /// The detector's corners, in order around it (top-left, top-right, bottom-right,
    /// bottom-left as the image shows them).
    pub detector_mm: [[f64; 3]; 4],
}

impl CArmSketch {
    /// The sketch of `carm`.
    pub fn of(carm: &CArm) -> Self {
        let r = carm.rotation();
        let (u, v, beam) = (r.row(0), r.row(1), r.row(2));
        let source = carm.source_mm();
        let centre = source + beam * carm.source_to_detector_mm;
        let half_u = carm.image_size.width as f64 * carm.pixel_pitch_mm / 2.0;
        let half_v = carm.image_size.height as f64 * carm.pixel_pitch_mm / 2.0;
        let corner = |su: f64, sv: f64| {
            ((centre + u * (su * half_u) + v * (sv * half_v)) * CARM_SKETCH_SCALE).0
        };
        Self {
            source_mm: (source * CARM_SKETCH_SCALE).0,
            detector_mm: [
                corner(-1.0, -1.0),
                corner(1.0, -1.0),
                corner(1.0, 1.0),
                corner(-1.0, 1.0),
            ],
        }
    }
}

/// Millimetres per newton of the 3D force arrows (0.3 N: 30 mm, beside a 50 mm catheter).
pub const ARROW_MM_PER_NEWTON: f64 = 100.0;

/// The 3D arrow of `force_n` (N) from `tip_mm`: its start and end, mm.
pub fn force_arrow_mm(tip_mm: [f64; 3], force_n: TipForce) -> [[f64; 3]; 2] {
    let end = [0, 1, 2].map(|i| tip_mm[i] + f64::from(force_n[i]) * ARROW_MM_PER_NEWTON);
    [tip_mm, end]
}

/// An arrow from `from` to `to` (canvas pixels) shortened along its direction so that its head
/// stays `margin` pixels inside a `side`-pixel square canvas (a zoomed view would otherwise run
/// it off the edge, hiding its head and so its direction). `None` when its tail is outside.
pub fn arrow_within(from: [f64; 2], to: [f64; 2], side: f64, margin: f64) -> Option<[f64; 2]> {
    let inside = |v: f64| (margin..=side - margin).contains(&v);
    if !inside(from[0]) || !inside(from[1]) {
        return None;
    }
    let mut t: f64 = 1.0;
    for axis in 0..2 {
        let d = to[axis] - from[axis];
        if d > 0.0 {
            t = t.min((side - margin - from[axis]) / d);
        } else if d < 0.0 {
            t = t.min((margin - from[axis]) / d);
        }
    }
    Some([0, 1].map(|i| from[i] + t * (to[i] - from[i])))
}

/// The catheter's points and the sketch's, for framing the 3D view.
pub fn scene_points(catheter: &Catheter3d, views: &Biplane) -> Vec<[f64; 3]> {
    let mut points = catheter.centreline_mm.clone();
    for carm in views.views() {
        let sketch = CArmSketch::of(carm);
        points.push(sketch.source_mm);
        points.extend(sketch.detector_mm);
    }
    points
}

#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;
    use crate::error_text::with_causes;

    #[test]
    fn an_arrow_is_shortened_to_keep_its_head_on_the_canvas() {
        // Inside: unchanged.
        assert_eq!(
            arrow_within([100.0, 100.0], [150.0, 120.0], 400.0, 8.0),
            Some([150.0, 120.0])
        );
        // Running off the right edge: cut where it meets the margin, along its direction.
        let head = arrow_within([300.0, 200.0], [500.0, 250.0], 400.0, 8.0).unwrap();
        assert!(
            (head[0] - 392.0).abs() < 1e-9 && (head[1] - 223.0).abs() < 1e-9,
            "{head:?}"
        );
        // Off the top and the left at once: the nearer edge cuts it.
        let head = arrow_within([50.0, 50.0], [-50.0, -150.0], 400.0, 8.0).unwrap();
        assert!((head[1] - 8.0).abs() < 1e-9 && head[0] > 8.0, "{head:?}");
        // Its tail off the canvas: not drawn.
        assert_eq!(arrow_within([-5.0, 50.0], [50.0, 50.0], 400.0, 8.0), None);
    }
    use crate::twin_live::XrayBackground;
    use crate::workspace::PairSource;
    use hnet_twin::vec3::Vec3;

    /// Distance between two points, mm.
    fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
        (Vec3(a) - Vec3(b)).norm()
    }

    fn twin(controls: TwinControls) -> LabeledPair {
        controls
            .render("t".into(), &XrayBackground::phantom())
            .unwrap()
    }

    fn run(pair: &LabeledPair) -> Result<Catheter3d, Catheter3dError> {
        let geometry = PairGeometry::of(pair, &TwinControls::default(), None)?;
        reconstruct_pair(
            &geometry,
            &PairMasks::of(pair, None, FitMasks::LabelsFirst)?,
        )
    }

    #[test]
    fn a_twin_pair_gives_its_catheter_and_force() {
        for force in [
            TipForce::new(0.15, 0.05, -0.10),
            TipForce::new(-0.2, 0.1, -0.05),
        ] {
            let controls = TwinControls {
                force_n: force,
                ..TwinControls::default()
            };
            let pair = twin(controls);
            let start = std::time::Instant::now();
            let c = run(&pair).unwrap();
            let millis = start.elapsed().as_secs_f64() * 1e3;
            let error = (c.force_n - force).max_abs();
            eprintln!(
                "{force:?}: physics {:?} N, error {error:.4} N, {:.1} mm, rms {:.3} mm, {millis:.0} ms",
                c.force_n, c.length_mm, c.rms_mm
            );
            assert!(error < 0.03, "{:?} N vs {force:?} N", c.force_n);
            assert!(c.tip_seen && c.length_mm > 30.0, "{}", c.summary());
            assert_eq!(c.masks, MaskOrigin::Labels);
            // Read blind: the catalogue catheter, the base fitted.
            assert!(c.base_fitted);
            assert!(c.summary().contains("read blind"), "{}", c.summary());
            // The reconstructed tip is the twin's.
            let PairSource::Twin { tip_mm, .. } = &pair.source else {
                unreachable!()
            };
            assert!(distance(c.tip_mm(), *tip_mm) < 2.0);
            assert!(c.summary().starts_with("catheter "), "{}", c.summary());
        }
    }

    #[test]
    fn h_nets_masks_are_used_when_the_pair_has_no_labels() {
        let mut pair = twin(TwinControls::default());
        let soft: Vec<Vec<f32>> = [&pair.mask_a, &pair.mask_b]
            .iter()
            .map(|m| m.iter().map(|&v| f32::from(v) / 255.0).collect())
            .collect();
        pair.masks_labeled = false;
        assert!(matches!(
            PairMasks::of(&pair, None, FitMasks::LabelsFirst),
            Err(Catheter3dError::NoMasks)
        ));
        let masks =
            PairMasks::of(&pair, Some([&soft[0], &soft[1]]), FitMasks::LabelsFirst).unwrap();
        assert_eq!(masks.source(), MaskOrigin::Predicted);
        let geometry = PairGeometry::of(&pair, &TwinControls::default(), None).unwrap();
        let c = reconstruct_pair(&geometry, &masks).unwrap();
        assert_eq!(c.masks, MaskOrigin::Predicted);
        // Only a rod fitted to H-Net's masks is combined with H-Net's force, with the fit's
        // standard error.
        let hnet = [0.3, 0.2, -0.3];
        let sd = c.force_sd_n.expect("a fitted rod has a standard error");
        assert_eq!(c.for_combination(), Some((c.force_n, Some(sd))));
        let combined = crate::force_reading::tests::bench_domain()
            .estimate(TipForce::from_newtons(hnet), c.for_combination());
        assert_eq!(
            combined.kind,
            hnet_twin::reconstruction::physics_force::EstimateKind::Combined
        );
        let labeled = run(&twin(TwinControls::default())).unwrap();
        assert_eq!(labeled.for_combination(), None);
        // Asked for, H-Net's masks are used also where the pair has labels; without them there
        // is nothing to fit.
        pair.masks_labeled = true;
        let chosen = PairMasks::of(&pair, Some([&soft[0], &soft[1]]), FitMasks::Hnet).unwrap();
        assert_eq!(chosen.source(), MaskOrigin::Predicted);
        assert!(matches!(
            PairMasks::of(&pair, None, FitMasks::Hnet),
            Err(Catheter3dError::NoPredictedMasks)
        ));
        for choice in [FitMasks::LabelsFirst, FitMasks::Hnet] {
            assert_eq!(FitMasks::from_value(choice.value()), Some(choice));
        }
    }

    #[test]
    fn an_uploaded_pair_is_read_with_the_default_views_and_a_fitted_base() {
        let twin_pair = twin(TwinControls::default());
        let mut pair = LabeledPair::new(
            "u".into(),
            PairSource::Upload {
                view_a: "a.png".into(),
                view_b: "b.png".into(),
                views: None,
            },
            twin_pair.view_a.clone(),
            twin_pair.view_b.clone(),
        );
        pair.mask_a = twin_pair.mask_a.clone();
        pair.mask_b = twin_pair.mask_b.clone();
        pair.masks_labeled = true;
        let geometry = PairGeometry::of(&pair, &TwinControls::default(), None).unwrap();
        assert_eq!(geometry.views, pair_views(&twin_pair));
        assert!(!geometry.base_known);
        let c = reconstruct_pair(
            &geometry,
            &PairMasks::of(&pair, None, FitMasks::LabelsFirst).unwrap(),
        )
        .unwrap();
        assert!(c.base_fitted);
        assert!(c.summary().contains("base pose fitted"));
        // An upload's C-arms are assumed, so its reprojection error checks nothing.
        assert!(geometry.views_assumed && c.views_assumed);
        assert!(
            c.summary().contains("no reprojection check"),
            "{}",
            c.summary()
        );
        assert!(!c.summary().contains("px mean reprojection error"));

        // Stated, its C-arms are read as given (here those a twin pair was rendered with, 30°
        // off the default), and the reprojection error is a check again.
        let turned = twin(TwinControls {
            view_a_deg: [30.0, 0.0],
            ..TwinControls::default()
        });
        let stated = crate::stated_geometry::StatedGeometry::of_views(&pair_views(&turned));
        let mut upload = pair.clone();
        upload.view_a = turned.view_a.clone();
        upload.view_b = turned.view_b.clone();
        upload.mask_a = turned.mask_a.clone();
        upload.mask_b = turned.mask_b.clone();
        let mut ws = crate::workspace::Workspace::default();
        ws.add(upload);
        assert!(ws.set_upload_views("u", Some(stated.views())));
        assert!(!ws.set_upload_views("nowhere", None));
        let upload = ws.pairs[0].clone();
        let geometry = PairGeometry::of(&upload, &TwinControls::default(), None).unwrap();
        assert!(!geometry.views_assumed);
        assert!((geometry.views.a.primary_deg - 30.0).abs() < 1e-9);
        let c = reconstruct_pair(
            &geometry,
            &PairMasks::of(&upload, None, FitMasks::LabelsFirst).unwrap(),
        )
        .unwrap();
        assert!(c.mean_residual_px < 1.0, "{}", c.summary());
        assert!(
            c.summary().contains("px mean reprojection error"),
            "{}",
            c.summary()
        );
        // A record from before the field existed reads as not stated.
        let json = serde_json::to_value(&pair.source).unwrap();
        assert!(
            json.get("Upload").is_some_and(|u| u.get("views").is_none()),
            "{json}"
        );
        let read: PairSource = serde_json::from_value(json).unwrap();
        assert_eq!(read, pair.source);
    }

    /// Each bad input is a typed error with a message naming the step and the view.
    #[test]
    fn bad_masks_and_cameras_get_their_message() {
        let good = twin(TwinControls::default());
        let message = |pair: &LabeledPair| with_causes(&run(pair).unwrap_err());

        let mut empty = good.clone();
        empty.mask_b.fill(0);
        assert_eq!(
            message(&empty),
            "no centreline in the label masks: view B: the mask is empty (no pixel reaches half \
             coverage)"
        );

        // A small blob in a corner, beside the catheter: set aside, and said so.
        let disc = |radius: f64| {
            let mut two = good.clone();
            crate::workspace::paint_disc(
                &mut two.mask_a,
                WORK_SIZE,
                20.0,
                20.0,
                radius,
                crate::workspace::Tool::Brush,
            );
            two
        };
        let small = run(&disc(6.0)).unwrap();
        assert_eq!(small.set_aside_px[1], Vec::<usize>::new());
        assert_eq!(small.set_aside_px[0].len(), 1);
        assert!(
            small.summary().ends_with(&format!(
                "; view A: a blob of {} px beside the catheter set aside",
                small.set_aside_px[0][0]
            )),
            "{}",
            small.summary()
        );
        // A blob as large as the catheter's: which is the catheter is not guessed.
        let catheter_px = good.mask_a.iter().filter(|&&b| b >= 128).count() as f64;
        let text = message(&disc((0.7 * catheter_px / std::f64::consts::PI).sqrt()));
        assert!(
            text.starts_with(
                "no centreline in the label masks: view A: the mask has 2 separate blobs"
            ),
            "{text}"
        );

        // Two views from the same place: no depth.
        let mut same = good.clone();
        if let PairSource::Twin { views, .. } = &mut same.source {
            views.b = views.a;
        }
        let text = message(&same);
        assert!(
            text.starts_with("the two views cannot be matched in 3D: the two views' centres are"),
            "{text}"
        );

        // A degenerate camera: no detector (zero pixel pitch gives an infinite focal length).
        let mut flat = good.clone();
        if let PairSource::Twin { views, .. } = &mut flat.source {
            views.a.source_to_detector_mm = 0.0;
        }
        let text = message(&flat);
        assert!(
            text.starts_with(
                "the two views cannot be matched in 3D: view A: unusable camera matrix"
            ),
            "{text}"
        );

        // A straight catheter in the plane of both sources (view B tilted cranially from view
        // A): it runs along the epipolar lines, no crossing locates a point in depth.
        let near = twin(TwinControls {
            force_n: TipForce::new(0.0, 0.1, -0.05),
            precurve_radius_mm: 0.0,
            view_b_deg: [0.0, 60.0],
            ..TwinControls::default()
        });
        let text = message(&near);
        assert!(
            text.starts_with(
                "the two views cannot be matched in 3D: only 0 points of the two centrelines lie on \
                 each other's epipolar lines"
            ),
            "{text}"
        );

        let mut unreadable = good.clone();
        if let PairSource::Twin { settings, .. } = &mut unreadable.source {
            settings["scene"] = serde_json::json!("nonsense");
        }
        assert!(message(&unreadable).starts_with("the pair's twin settings cannot be read"));
    }

    #[test]
    fn a_rod_that_does_not_fit_is_reported() {
        let pair = twin(TwinControls::default());
        let geometry = PairGeometry::of(&pair, &TwinControls::default(), None).unwrap();
        let masks = PairMasks::of(&pair, None, FitMasks::LabelsFirst).unwrap();
        // A catheter far too stiff to bend this way within the largest force considered.
        let stiff = PairGeometry {
            rod: geometry.rod.clone().with_bending_stiffness(1e9),
            base_known: true,
            blind: None,
            ..geometry.clone()
        };
        let err = reconstruct_pair(&stiff, &masks).unwrap_err();
        assert!(matches!(err, Catheter3dError::PoorFit { .. }), "{err:?}");
        assert!(
            with_causes(&err).starts_with("no physics estimate: the best-fitting rod stays"),
            "{err}"
        );
        // Views where the straight catheter nearly lies in the plane of both sources: the rod
        // solver fails around the forces that would fit.
        let ill = twin(TwinControls {
            force_n: TipForce::new(0.0, 0.1, -0.05),
            precurve_radius_mm: 0.0,
            view_b_deg: [5.0, 60.0],
            ..TwinControls::default()
        });
        let text = with_causes(&run(&ill).unwrap_err());
        assert!(
            text.starts_with("no physics estimate: the rod fit did not converge"),
            "{text}"
        );
        // A rod that cannot be solved at all.
        let mut broken = PairGeometry {
            base_known: true,
            blind: None,
            ..geometry.clone()
        };
        broken.rod.length_mm = 0.0;
        let err = reconstruct_pair(&broken, &masks).unwrap_err();
        assert!(
            with_causes(&err).starts_with(
                "no physics estimate: the rod solver failed at the fit's starting point"
            ),
            "{err}"
        );
    }

    #[test]
    fn the_epipolar_line_of_a_point_passes_through_its_match() {
        let views = default_views();
        let point = Vec3::new(5.0, -3.0, -20.0);
        let [a, b] = [views.a.project(point), views.b.project(point)];
        let [p, q] = epipolar_line(&views, View::B, [a.u, a.v]).unwrap();
        // The distance of b from the segment's line.
        let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
        let off = ((b.u - p[0]) * dy - (b.v - p[1]) * dx).abs() / dx.hypot(dy);
        assert!(off < 1e-6, "{off}");
        let [p, _] = epipolar_line(&views, View::A, [b.u, b.v]).unwrap();
        assert!((0.0..=WORK_SIZE.width as f64 + 1e-6).contains(&p[0]));
        assert!((0.0..=WORK_SIZE.height as f64 + 1e-6).contains(&p[1]));
    }

    #[test]
    fn the_sketch_keeps_the_c_arms_directions() {
        let views = default_views();
        let a = CArmSketch::of(&views.a);
        // View A's source is posterior (-y), its detector anterior, at a tenth of their size.
        assert!((a.source_mm[1] + 75.0).abs() < 1e-9, "{:?}", a.source_mm);
        let centre_y = a.detector_mm.iter().map(|c| c[1]).sum::<f64>() / 4.0;
        assert!((centre_y - 45.0).abs() < 1e-9);
        assert!((distance(a.detector_mm[0], a.detector_mm[1]) - 15.0).abs() < 1e-9);
        let b = CArmSketch::of(&views.b);
        assert!(b.source_mm[0] < -74.0, "{:?}", b.source_mm);
        let arrow = force_arrow_mm([1.0, 2.0, 3.0], TipForce::new(0.1, 0.0, -0.2));
        assert!((distance(arrow[0], arrow[1]) - 0.05f64.sqrt() * 100.0).abs() < 1e-4);
    }
}
