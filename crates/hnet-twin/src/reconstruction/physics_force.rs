//! From a stereo pair's two masks to the catheter in 3D and its physics-checked tip force, in one
//! call that `hnet eval`, the page and the tests share: a centreline in each view
//! ([`crate::reconstruction::centreline`]), their epipolar matching and triangulation
//! ([`crate::reconstruction::epipolar`]), and the twin's rod fitted to the result ([`crate::reconstruction::rod_fit`]).

use serde::{Deserialize, Serialize};

use crate::reconstruction::catalogue::CatalogueCatheter;
use crate::reconstruction::centreline::{
    Centreline, CentrelineError, CentrelineSettings, Mask, extract_centreline,
};
use crate::reconstruction::epipolar::{
    Reconstruction, ReconstructionError, ReconstructionSettings, proximal_hint_px, reconstruct,
};
use crate::reconstruction::rod_fit::{
    RodFit, RodFitError, RodFitSettings, fit_rod_to_reconstruction,
};
use crate::simulator::carm::CameraMatrix;
use crate::simulator::rod::{RodBase, RodConfig, RodShape};
use crate::simulator::scene::NominalBase;
use crate::vec3::Vec3;

mod combination;
mod stack;
pub use combination::{
    CalibrationPair, EstimateKind, ForceCombination, INTERVAL_90_Z, MIN_CALIBRATION_PAIRS,
    TipForceEstimate, conformal_quantile, head_withheld,
};
pub use stack::{FOLDS, LinearStack, MIN_STACK_GAIN, MIN_STACK_PAIRS};

/// Weight of the seen tip in a blind fit ([`RodFitSettings::tip_weight`], in centreline
/// points). With the base fitted, the reconstructed tip pins where along its axis the base sits
/// (the catheter's flexible length lies between them), which an axial push otherwise trades
/// against; with an exact base the tip only adds its own noise (the default weight, 0).
/// Measured blind from the bundled weights' masks on fresh bench pairs: the combined estimate's
/// mean R² 0.77 → 0.82 and 0.80 → 0.83 on two sets at weight 1, no better at 2 or 3, and no
/// worse from true masks (docs/results.md, "The tip in a blind fit"). Where the rod reaches the
/// tip only with its base out of tolerance, or not at all (a catheter longer than its catalogue
/// entry), [`physics_estimate`] sets the tip aside ([`TipUse::SetAside`]): weighed always, it
/// left 3.5 % of the mismatch suite's `length+5mm` pairs with an estimate, set aside 75 %.
pub const BLIND_TIP_WEIGHT: f64 = 1.0;

/// Least angle between the two views' rays at the catheter for a blind read
/// ([`ReconstructionSettings::min_triangulation_deg`], degrees; the exact setup keeps the
/// default 10°). With the base fitted, depth is what places the base and bends the rod: off the
/// bench (fresh pairs at the page's C-arm angles, a catalogue catheter, the base anywhere), the
/// physics estimate's R² from the bundled weights' masks was -2.5 to -15 on every axis for views
/// under 30° apart, and leaving them out lifted the combined estimate's (docs/results.md, "Force
/// without the twin's answers").
pub const BLIND_MIN_TRIANGULATION_DEG: f64 = 30.0;

/// What the masks are read with: both views' cameras, the catheter as the rod model knows it,
/// and how each step works.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicsSetup {
    /// Projection matrices of view A and view B at the masks' size (world mm to pixels).
    pub cameras: [CameraMatrix; 2],
    /// The catheter's flexible section (length, stiffness, pre-curvature).
    pub rod: RodConfig,
    /// Where and how it is clamped (exact for twin pairs; fit it with
    /// [`RodFitSettings::fit_base_position`] when it is only roughly known).
    pub base: RodBase,
    /// Centreline extraction (its proximal hint is set from the base for each view).
    pub centreline: CentrelineSettings,
    /// Matching and triangulation.
    pub reconstruction: ReconstructionSettings,
    /// What is fitted.
    pub fit: RodFitSettings,
    /// Largest RMS distance of the reconstruction from the fitted rod whose force is given, mm
    /// ([`MAX_FIT_RMS_MM`]); `None` gives every fit's force.
    pub max_fit_rms_mm: Option<f64>,
}

/// Largest RMS distance between the reconstruction and the fitted rod for which a blind estimate
/// (and the page) gives the rod's force, mm. A twin pair's exact masks fit within 0.04 mm at the
/// page's working size, and true masks at 128 px within 0.3 mm; 1 mm is 2.4 pixels at the
/// isocentre at 224 px (0.42 mm per pixel), far beyond any mask's own error, so a worse fit means
/// the rod model does not describe what was reconstructed.
pub const MAX_FIT_RMS_MM: f64 = 1.0;

impl PhysicsSetup {
    /// The default settings of every step for these cameras and this catheter.
    pub fn new(cameras: [CameraMatrix; 2], rod: RodConfig, base: RodBase) -> Self {
        Self {
            cameras,
            rod,
            base,
            centreline: CentrelineSettings::default(),
            reconstruction: ReconstructionSettings::default(),
            fit: RodFitSettings::default(),
            max_fit_rms_mm: None,
        }
    }

    /// What a user has, and nothing of the pair's own record: `cameras` from the C-arm
    /// geometry a DICOM header gives (angles, distances, pixel spacing), the catalogue's
    /// `catheter`, and a `nominal_base` (the fixture's nominal pose, or the page's catheter
    /// settings) whose position and orientation are fitted with the force, kept within its
    /// tolerance unless the shape says otherwise. Views under [`BLIND_MIN_TRIANGULATION_DEG`]
    /// apart at the catheter, and fits farther than [`MAX_FIT_RMS_MM`] from the reconstruction,
    /// give no force.
    pub fn blind(
        cameras: [CameraMatrix; 2],
        catheter: &CatalogueCatheter,
        nominal_base: &NominalBase,
    ) -> Self {
        let mut setup = Self::new(
            cameras,
            catheter.rod(&RodConfig::default()),
            nominal_base.base,
        );
        setup.fit.fit_base_position = true;
        setup.fit.fit_base_rotation = true;
        setup.fit.base_prior = Some(nominal_base.tolerance);
        setup.fit.start_base_from_centreline = true;
        setup.max_fit_rms_mm = Some(MAX_FIT_RMS_MM);
        setup.fit.tip_weight = BLIND_TIP_WEIGHT;
        setup.reconstruction.min_triangulation_deg = BLIND_MIN_TRIANGULATION_DEG;
        setup
    }
}

/// The catheter in 3D and the force of the rod that fits it.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicsEstimate {
    /// The centreline of view A and of view B, pixels.
    pub centrelines: [Centreline; 2],
    /// The triangulated 3D centreline, mm.
    pub reconstruction: Reconstruction,
    /// The fitted rod: its tip force (N), shape and distance from the reconstruction.
    pub fit: RodFit,
    /// What the fit made of the tip seen in both views.
    pub tip: TipUse,
}

/// What a blind fit made of the catheter's tip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TipUse {
    /// Not weighed: not seen in both views, or a fit that does not weigh it (an exact base).
    NotWeighed,
    /// Weighed ([`BLIND_TIP_WEIGHT`]): it pins where along its axis the base sits.
    Weighed,
    /// Set aside: the rod reached it only with its base out of tolerance or far from the
    /// catheter (a flexible length other than the catalogue's), so the shape was read without it.
    SetAside,
}

/// Which step could not be done, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// A mask gives no centreline (empty, several blobs, not a tube, too short).
    #[error(transparent)]
    Centreline(#[from] CentrelineError),
    /// The two centrelines cannot be matched in 3D.
    #[error(transparent)]
    Reconstruction(#[from] ReconstructionError),
    /// No rod fits the reconstruction.
    #[error(transparent)]
    Fit(#[from] RodFitError),
    /// The best rod stays far from the reconstruction: the catheter's settings, the views or the
    /// masks do not describe this catheter, and its force would mean nothing.
    #[error(
        "the best-fitting rod stays {rms_mm:.2} mm RMS from the reconstructed catheter (at most \
         {limit_mm} mm accepted); the catheter's settings, the C-arm geometry or the masks do not \
         match this pair"
    )]
    PoorFit {
        /// RMS distance of the reconstruction from the fitted rod, mm.
        rms_mm: f64,
        /// The limit, mm.
        limit_mm: f64,
    },
    /// The rod fits only with its base far outside the nominal pose's tolerance: the catheter
    /// assumed is not this one, or the geometry is wrong.
    #[error(
        "the rod fits only with its base {offset_mm:.1} mm and {tilt_deg:.0}° from the nominal \
         pose, beyond {MAX_BASE_SDS} standard deviations of its tolerance; the catheter assumed or \
         the C-arm geometry does not match this pair"
    )]
    BaseOutsideTolerance {
        /// Distance of the fitted base from the nominal one, mm.
        offset_mm: f64,
        /// Angle between their axes, degrees.
        tilt_deg: f64,
    },
    /// The fitted force ran into the largest force the fit considers
    /// ([`RodFitSettings::max_force_n`]): the fit was stopped by that bound, not by the shape,
    /// so its force is no estimate.
    #[error(
        "the rod fits only with a tip force of {force_n:.2} N, at the fit's limit of {limit_n} N: \
         the shape does not say the force (the catheter assumed, the C-arm geometry or the masks \
         do not match this pair)"
    )]
    AtForceLimit {
        /// Magnitude of the fitted force, N.
        force_n: f64,
        /// The fit's limit, N.
        limit_n: f64,
    },
    /// With the seen tip set aside, the rod fits only by running on past where both views show
    /// the catheter end: the catheter assumed is longer than this one.
    #[error(
        "the rod fits only by running {beyond_mm:.0} mm past the tip both views show (at most \
         {MAX_ROD_BEYOND_SEEN_TIP_MM} mm accepted): the catheter assumed is longer than this one"
    )]
    RodBeyondSeenTip {
        /// The rod's length beyond its point nearest the seen tip, mm.
        beyond_mm: f64,
    },
}

/// How far a rod fitted with the seen tip set aside ([`TipUse::SetAside`]) may run on past the
/// point nearest that tip, mm: twice the catalogue's realistic error in flexible length (±5 mm,
/// the mismatch suite's `length+5mm`). Beyond it, the catheter assumed is longer than the one
/// both views show ending there ([`PhysicsError::RodBeyondSeenTip`]).
pub const MAX_ROD_BEYOND_SEEN_TIP_MM: f64 = 10.0;

/// The arc length of `shape` beyond its point nearest `seen_tip_mm`, mm.
fn rod_beyond_mm(shape: &RodShape, seen_tip_mm: Vec3) -> f64 {
    let nearest = shape
        .points_mm
        .iter()
        .map(|p| (*p - seen_tip_mm).norm())
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(at, _)| at);
    let length = shape.arc_mm.last().copied().unwrap_or(0.0);
    length - shape.arc_mm.get(nearest).copied().unwrap_or(length)
}

/// Share of [`RodFitSettings::max_force_n`] at which a fitted force counts as stopped by that
/// bound ([`PhysicsError::AtForceLimit`]). Read blind from exact masks at the page's C-arm
/// angles, one fit in 234 ended there (1.99 N against a true 0.21 N, its base 12 mm and 65°
/// off); refusing it lifted `hnet eval`'s physics R² from true masks on that set (s37) from 0.23
/// to 0.85 (docs/log/2026-12-06-tangled-blobs-and-parallel-views.md).
pub const AT_FORCE_LIMIT_SHARE: f64 = 0.95;

/// How many standard deviations of a [`crate::reconstruction::rod_fit::BasePrior`] a fitted base may lie from
/// the nominal pose (per component of its offset, or in tilt) before its force is refused.
pub const MAX_BASE_SDS: f64 = 4.0;

impl PhysicsError {
    /// The failing step, and for a centreline the check that failed (`centreline: not a
    /// tube`), for counts that say what to fix.
    pub fn counted_as(&self) -> String {
        match self {
            Self::Centreline(e) => format!("{}: {}", self.step(), e.kind()),
            _ => self.step().to_string(),
        }
    }

    /// A short name of the failing step (`centreline`, `reconstruction`, `fit`), for counts.
    pub fn step(&self) -> &'static str {
        match self {
            Self::Centreline(_) => "centreline",
            Self::Reconstruction(_) => "reconstruction",
            Self::Fit(_) => "fit",
            Self::PoorFit { .. } => "poor fit",
            Self::BaseOutsideTolerance { .. } => "base outside tolerance",
            Self::AtForceLimit { .. } => "force at the fit's limit",
            Self::RodBeyondSeenTip { .. } => "rod beyond the seen tip",
        }
    }
}

/// Reconstructs the catheter of `masks` (view A, view B) in 3D and fits the rod to it.
pub fn physics_estimate(
    masks: [Mask<'_>; 2],
    setup: &PhysicsSetup,
) -> Result<PhysicsEstimate, PhysicsError> {
    let [mask_a, mask_b] = masks;
    let centreline = |mask: &Mask<'_>, view: usize, name: &str| {
        let settings = CentrelineSettings {
            proximal_hint_px: proximal_hint_px(&setup.cameras[view], &setup.base),
            ..setup.centreline.clone()
        };
        extract_centreline(mask, name, &settings)
    };
    let centrelines = [centreline(&mask_a, 0, "A")?, centreline(&mask_b, 1, "B")?];
    let reconstruction = reconstruct(
        &centrelines[0],
        &setup.cameras[0],
        &centrelines[1],
        &setup.cameras[1],
        &setup.reconstruction,
    )?;
    let (fit, tip) = match checked_fit(setup, &reconstruction, &setup.fit) {
        // The seen tip pins the base only when the catalogue's flexible length agrees with it: a
        // catheter longer or shorter than its entry fits the tip only with its base pulled out
        // of tolerance, or not at all. Its shape is read again without the tip.
        Err(
            PhysicsError::PoorFit { .. }
            | PhysicsError::BaseOutsideTolerance { .. }
            | PhysicsError::AtForceLimit { .. }
            | PhysicsError::Fit(RodFitError::NotConverged { .. }),
        ) if setup.fit.tip_weight > 0.0 && reconstruction.tip_seen => {
            let without_tip = RodFitSettings {
                tip_weight: 0.0,
                ..setup.fit.clone()
            };
            let fit = checked_fit(setup, &reconstruction, &without_tip)?;
            // Set aside, the tip no longer stops a catalogue's catheter longer than the one
            // seen from running on past where both views show it end.
            let seen_tip = reconstruction.points_mm[reconstruction.points_mm.len() - 1];
            let beyond_mm = rod_beyond_mm(&fit.shape, seen_tip);
            if beyond_mm > MAX_ROD_BEYOND_SEEN_TIP_MM {
                return Err(PhysicsError::RodBeyondSeenTip { beyond_mm });
            }
            (fit, TipUse::SetAside)
        }
        fit => (
            fit?,
            if setup.fit.tip_weight > 0.0 && reconstruction.tip_seen {
                TipUse::Weighed
            } else {
                TipUse::NotWeighed
            },
        ),
    };
    Ok(PhysicsEstimate {
        centrelines,
        reconstruction,
        fit,
        tip,
    })
}

/// A fitted base rotation's fit that converged farther than this from the reconstruction (RMS,
/// mm) is tried again from other starts ([`RESTART_ROLLS_RAD`], then the nominal base), and the
/// first that lands within it replaces it. Read blind from label masks on the stiff set (s36),
/// good fits stay within 0.2 mm; fits that stopped where a large force bends the rod against
/// its pre-curve (0.5-0.8 N against a true 0.05-0.1 N), 0.49-0.56 mm. A fit that did not
/// converge is not restarted: at the page's C-arm angles (s37) restarts of such fits converged
/// on forces of 1.4-1.7 N against a few tenths.
pub const RESTART_RMS_MM: f64 = 0.3;

/// The rolls of the base about its axis a restarted fit starts from, rad: the pre-curve's plane
/// a quarter, a half and three quarters of a turn from the first start's.
pub const RESTART_ROLLS_RAD: [f64; 3] = [
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::PI,
    -std::f64::consts::FRAC_PI_2,
];

/// The rod fitted to `reconstruction` with `settings`, restarted from other starts when it
/// converged with a fitted base far from the reconstruction ([`RESTART_RMS_MM`]).
fn fit_with_restarts(
    setup: &PhysicsSetup,
    reconstruction: &Reconstruction,
    settings: &RodFitSettings,
) -> Result<RodFit, RodFitError> {
    let first = fit_rod_to_reconstruction(&setup.rod, &setup.base, reconstruction, settings)?;
    if !settings.fit_base_rotation || first.rms_mm <= RESTART_RMS_MM {
        return Ok(first);
    }
    let rolled = RESTART_ROLLS_RAD.iter().map(|&roll| RodFitSettings {
        start_roll_rad: roll,
        ..settings.clone()
    });
    let nominal = settings.start_base_from_centreline.then(|| RodFitSettings {
        start_base_from_centreline: false,
        ..settings.clone()
    });
    let closer = rolled.chain(nominal).find_map(|start| {
        fit_rod_to_reconstruction(&setup.rod, &setup.base, reconstruction, &start)
            .ok()
            .filter(|fit| fit.rms_mm <= RESTART_RMS_MM)
    });
    Ok(closer.unwrap_or(first))
}

/// The rod fitted to `reconstruction` with `settings`, refused when it stays far from the
/// reconstruction, or its force runs into the fit's limit, or it puts its base outside the
/// nominal pose's tolerance (checked in that order).
fn checked_fit(
    setup: &PhysicsSetup,
    reconstruction: &Reconstruction,
    settings: &RodFitSettings,
) -> Result<RodFit, PhysicsError> {
    let fit = fit_with_restarts(setup, reconstruction, settings)?;
    if let Some(limit_mm) = setup.max_fit_rms_mm
        && (fit.rms_mm.is_nan() || fit.rms_mm > limit_mm)
    {
        return Err(PhysicsError::PoorFit {
            rms_mm: fit.rms_mm,
            limit_mm,
        });
    }
    let force_n = f64::from(fit.force_n.magnitude());
    if settings.fit_force && force_n >= AT_FORCE_LIMIT_SHARE * settings.max_force_n {
        return Err(PhysicsError::AtForceLimit {
            force_n,
            limit_n: settings.max_force_n,
        });
    }
    if let Some(prior) = settings.base_prior {
        let offset = fit.base.position_mm - setup.base.position_mm;
        let tilt_deg = fit
            .base
            .orientation
            .column(2)
            .dot(setup.base.orientation.column(2))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        if offset.max_abs() > MAX_BASE_SDS * prior.position_sd_mm
            || tilt_deg > MAX_BASE_SDS * prior.tilt_sd_deg * 2f64.sqrt()
        {
            return Err(PhysicsError::BaseOutsideTolerance {
                offset_mm: offset.norm(),
                tilt_deg,
            });
        }
    }
    Ok(fit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reconstruction::epipolar::tests::bench_sample;
    use hnet_units::TipForce;

    #[test]
    fn conformal_intervals_cover_what_they_promise() {
        let mut scores: Vec<f64> = (1..=19).map(f64::from).collect();
        // 19 scores: rank ⌈0.9·20⌉ = 18.
        assert_eq!(conformal_quantile(&mut scores, 0.9), Some(18.0));
        assert_eq!(conformal_quantile(&mut [3.0, 1.0], 0.9), Some(3.0));
        assert_eq!(conformal_quantile(&mut [], 0.9), None);
        // Heavy-tailed errors a normal interval would under-cover: calibrated on 200 pairs, the
        // interval covers about 90 % of 2,000 more of the same kind.
        let mut state = 7u64;
        let mut heavy = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = ((state >> 11) as f64 / (1u64 << 53) as f64).clamp(1e-9, 1.0 - 1e-9);
            // A Cauchy-like tail, scaled.
            0.02 * (std::f64::consts::PI * (u - 0.5)).tan().clamp(-20.0, 20.0)
        };
        let mut pair = || {
            let truth_n = TipForce::new(0.1, -0.05, -0.2);
            CalibrationPair {
                truth_n,
                network_n: truth_n.map(|t| t + heavy() as f32),
                physics_n: truth_n.map(|t| t + heavy() as f32),
                physics_sd_n: [0.02; 3],
            }
        };
        let calibration: Vec<CalibrationPair> = (0..200).map(|_| pair()).collect();
        let c = ForceCombination::calibrate(&calibration).unwrap();
        let tests: Vec<CalibrationPair> = (0..2000).map(|_| pair()).collect();
        for axis in 0..3 {
            let covered = tests
                .iter()
                .filter(|p| {
                    let (force, sd) =
                        c.combine_with_sd(p.network_n, p.physics_n, Some(p.physics_sd_n));
                    (force[axis] - p.truth_n[axis]).abs() <= c.interval_90_n(sd)[axis]
                })
                .count() as f64
                / tests.len() as f64;
            assert!((0.85..=0.95).contains(&covered), "axis {axis}: {covered}");
            // The network's own interval, for pairs without a physics estimate, too.
            let head = c.head_interval_90_n()[axis];
            let covered = tests
                .iter()
                .filter(|p| (p.network_n[axis] - p.truth_n[axis]).abs() <= head)
                .count() as f64
                / tests.len() as f64;
            assert!(
                (0.85..=0.95).contains(&covered),
                "head, axis {axis}: {covered}"
            );
        }
    }

    #[test]
    fn the_combination_weighs_each_estimate_by_its_calibrated_error() {
        // Network off by ±0.06 N on every axis; physics off by 3·0.6745 of its fit's standard
        // error (0.01 N): calibrated, σ_network = 0.06 N and σ_physics = 3 · 0.01 N.
        let pairs: Vec<CalibrationPair> = (0..20)
            .map(|i| {
                let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                let truth_n = TipForce::new(0.1 * i as f32 / 20.0, -0.05, -0.2);
                CalibrationPair {
                    truth_n,
                    network_n: truth_n.map(|t| t + 0.06 * sign),
                    physics_n: truth_n.map(|t| t - 0.03 * 0.674_489_75 * sign),
                    physics_sd_n: [0.01; 3],
                }
            })
            .collect();
        let c = ForceCombination::calibrate(&pairs).unwrap();
        assert_eq!(c.pairs, 20);
        for e in c.network_error_n {
            assert!((e - 0.06).abs() < 1e-6, "{c:?}");
        }
        assert!((c.physics_sd_scale - 3.0).abs() < 1e-4, "{c:?}");
        // Variances 0.0036 and 0.0009: the physics estimate weighs 0.8.
        let (network, physics) = (TipForce::new(0.1, 0.1, 0.1), TipForce::ZERO);
        let combined = c.combine(network, physics, Some([0.01; 3]));
        for v in combined.newtons() {
            assert!((v - 0.02).abs() < 1e-6, "{combined:?}");
        }
        // A fit whose shape says little about an axis leaves it to the network.
        let vague = c.combine(network, physics, Some([0.01, 0.01, 1.0]));
        assert!(vague[2] > 0.099, "{vague:?}");
        // Without a standard error, both weigh the same.
        assert_eq!(c.combine(network, physics, None), network.map(|f| f / 2.0));
        assert_eq!(ForceCombination::calibrate(&pairs[..9]), None);
        // Without a physics estimate, the network's force with its own interval; with one, the
        // combination with the combined interval.
        let alone = c.estimate(TipForce::new(0.3, 0.0, 0.0), None);
        assert_eq!(alone.kind, EstimateKind::Head);
        assert_eq!(alone.force_n, TipForce::new(0.3, 0.0, 0.0));
        let head = alone.interval_90_n.unwrap();
        assert!(head.iter().all(|h| (h - 0.06).abs() < 1e-6));
        let both = c.estimate(network, Some((physics, Some([0.01; 3]))));
        assert_eq!(both.kind, EstimateKind::Combined);
        assert!(both.interval_90_n.unwrap()[0] < head[0]);
        // A fit without a standard error is not combined: the intervals were not calibrated
        // for it.
        assert_eq!(
            c.estimate(network, Some((physics, None))).kind,
            EstimateKind::Head
        );
        // At C-arm angles the head was not trained at, the head alone is withheld, saying
        // why; combined, the estimate stands.
        let off = ["view A at -20°/+10° (trained at +0°/+0°)".to_string()];
        let why = c.estimate_at(network, None, &off).unwrap_err();
        assert!(
            why.starts_with("no physics estimate") && why.contains(&off[0]),
            "{why}"
        );
        assert_eq!(
            c.estimate_at(network, None, &[]),
            Ok(c.estimate(network, None))
        );
        assert_eq!(
            c.estimate_at(network, Some((physics, Some([0.01; 3]))), &off),
            Ok(both)
        );
        // An older combination without the network's measured interval reads a normal's.
        let older = ForceCombination {
            network_interval_90_n: None,
            ..c
        };
        assert!((older.head_interval_90_n()[0] - 0.06 * 1.644_853_6).abs() < 1e-6);
        // |F| over the box of the intervals.
        let estimate = TipForceEstimate {
            force_n: TipForce::new(0.3, 0.0, 0.0),
            interval_90_n: Some([0.1; 3]),
            kind: EstimateKind::Head,
        };
        let (low, high) = estimate.magnitude_range_n().unwrap();
        assert!((low - 0.2).abs() < 1e-6, "{low}");
        assert!((high - (0.16f32 + 0.02).sqrt()).abs() < 1e-6, "{high}");
        assert_eq!(
            TipForceEstimate::uncalibrated(network).magnitude_range_n(),
            None
        );
    }

    #[test]
    fn a_twin_pair_gives_its_force_back_and_an_empty_mask_is_named() {
        let (config, sample) = bench_sample(128, 11, 0);
        let (rod, base) = sample.params.rod(&config.rod);
        let setup = PhysicsSetup::new(
            [
                config.views.a.camera_matrix(),
                config.views.b.camera_matrix(),
            ],
            rod,
            base,
        );
        let mask = |i: usize| Mask::coverage8(128, 128, &sample.views[i].mask);
        let estimate = physics_estimate([mask(0), mask(1)], &setup).unwrap();
        let error = (estimate.fit.force_n - sample.params.tip_force_n).magnitude();
        assert!(error < 0.03, "force off by {error} N");

        let empty = vec![0u8; 128 * 128];
        let err =
            physics_estimate([mask(0), Mask::coverage8(128, 128, &empty)], &setup).unwrap_err();
        assert_eq!(err.step(), "centreline");
        assert!(
            err.counted_as().starts_with("centreline: "),
            "{}",
            err.counted_as()
        );
        assert!(err.to_string().starts_with("view B"), "{err}");
    }

    /// Off the bench (the page's C-arm angles, the base anywhere in its ranges, the catalogue's
    /// catheter: the `catalogue-anywhere` mismatch set), exact masks read blind give the force
    /// back on nearly every pair that is read: what limits that set is the masks, not the free
    /// base. `HNET_STUDY_PAIRS=300` runs the 300 pairs of docs/log (with `-- --nocapture`).
    #[test]
    fn blind_reads_at_the_pages_c_arm_angles_from_exact_masks() {
        use crate::reconstruction::catalogue::{BENCH_CATHETER, CatalogueCatheter};
        use crate::simulator::off_bench::OffBench;
        use crate::simulator::scene::{Modality, SceneSampling, TwinConfig};
        use hnet_units::ImageSize;
        let scenes: SceneSampling = serde_json::from_str(include_str!(
            "../../../../configs/mismatch/catalogue-anywhere.json"
        ))
        .unwrap();
        let nominal = scenes.nominal_base();
        let size = ImageSize::square(224);
        let pairs = TwinConfig::new(Modality::Xray2, size);
        let pairs = OffBench::new(pairs, Vec::new(), 0.0).with_scenes(scenes);
        let catheter = CatalogueCatheter::find(BENCH_CATHETER).unwrap();
        let count: u64 = std::env::var("HNET_STUDY_PAIRS")
            .ok()
            .and_then(|n| n.parse().ok())
            .unwrap_or(30);
        let (mut truth, mut read, mut refused) = (Vec::new(), Vec::new(), 0);
        for index in 0..count {
            let (config, sample) = pairs.generate(37, index).unwrap();
            let cameras = [
                config.views.a.camera_matrix(),
                config.views.b.camera_matrix(),
            ];
            let mask = |i: usize| Mask::coverage8(224, 224, &sample.views[i].mask);
            let blind = PhysicsSetup::blind(cameras, &catheter, &nominal);
            match physics_estimate([mask(0), mask(1)], &blind) {
                Ok(estimate) => {
                    truth.push(sample.params.tip_force_n);
                    read.push(estimate.fit.force_n);
                }
                Err(_) => refused += 1,
            }
        }
        let mut errors: Vec<f32> = truth
            .iter()
            .zip(&read)
            .map(|(t, r)| (*r - *t).magnitude())
            .collect();
        errors.sort_by(f32::total_cmp);
        let median = errors[errors.len() / 2];
        let far = errors.iter().filter(|&&e| e > 0.15).count();
        eprintln!(
            "{} read, {refused} refused; error median {median:.3} N, {far} beyond 0.15 N",
            read.len()
        );
        assert!(read.len() as u64 >= count * 2 / 3, "{} read", read.len());
        assert!(median < 0.02, "median error {median} N");
        assert!(
            far * 20 <= read.len(),
            "{far} of {} beyond 0.15 N",
            read.len()
        );
    }

    /// Two pairs of the stiff set (x1.3, base anywhere: `hnet simulate --seed 36 --scene-sampling
    /// configs/mismatch/stiff-anywhere.json`, samples 19 and 194), read blind from their exact
    /// masks with the catheter calibrated (x1.307): the first fit stopped 0.5 mm from the
    /// reconstruction with 0.7-0.9 N against a true 0.07-0.13 N; restarted, the force is found.
    #[test]
    fn a_fit_stopped_far_from_the_catheter_is_restarted() {
        use crate::reconstruction::catalogue::{BENCH_CATHETER, CatalogueCatheter};
        use crate::simulator::scene::{Backgrounds, Modality, SceneSampling, TwinConfig, generate};
        use hnet_units::ImageSize;
        let scenes: SceneSampling = serde_json::from_str(include_str!(
            "../../../../configs/mismatch/stiff-anywhere.json"
        ))
        .unwrap();
        let nominal = scenes.nominal_base();
        let mut twin = TwinConfig::new(Modality::Xray2, ImageSize::square(224));
        twin.scene = scenes;
        let backgrounds = Backgrounds::phantom(&twin.views);
        let bench = CatalogueCatheter::find(BENCH_CATHETER).unwrap();
        let catheter = CatalogueCatheter {
            bending_stiffness_n_m2: bench.bending_stiffness_n_m2 * 1.307,
            ..bench
        };
        let cameras = [twin.views.a.camera_matrix(), twin.views.b.camera_matrix()];
        let blind = PhysicsSetup::blind(cameras, &catheter, &nominal);
        for index in [19, 194] {
            let sample = generate(&twin, &backgrounds, 36, index).unwrap();
            let mask = |i: usize| Mask::coverage8(224, 224, &sample.views[i].mask);
            let estimate = physics_estimate([mask(0), mask(1)], &blind).unwrap();
            let error = (estimate.fit.force_n - sample.params.tip_force_n).max_abs();
            assert!(
                error < 0.03 && estimate.fit.rms_mm <= RESTART_RMS_MM,
                "{index}: {:?} N against {:?} N, {:.3} mm",
                estimate.fit.force_n,
                sample.params.tip_force_n,
                estimate.fit.rms_mm
            );
        }
    }

    /// Read blind (the catalogue's bench catheter, the base fitted from the fixture's nominal
    /// pose within its tolerance, never the pair's own record), a twin pair's exact masks give
    /// its force back nearly as well as with its recorded base; the prior on the base changes
    /// little where the shape decides (exact masks fit within hundredths of a millimetre).
    #[test]
    fn a_twin_pair_read_blind_gives_its_force_back() {
        use crate::reconstruction::catalogue::{BENCH_CATHETER, CatalogueCatheter};
        use crate::simulator::scene::SceneSampling;
        let catheter = CatalogueCatheter::find(BENCH_CATHETER).unwrap();
        let nominal = SceneSampling::bench().nominal_base();
        for index in 0..3 {
            let (config, sample) = bench_sample(128, 11, index);
            let cameras = [
                config.views.a.camera_matrix(),
                config.views.b.camera_matrix(),
            ];
            let mask = |i: usize| Mask::coverage8(128, 128, &sample.views[i].mask);
            let blind = PhysicsSetup::blind(cameras, &catheter, &nominal);
            assert_eq!(blind.max_fit_rms_mm, Some(MAX_FIT_RMS_MM));
            assert_eq!(
                blind.reconstruction.min_triangulation_deg,
                BLIND_MIN_TRIANGULATION_DEG
            );
            let estimate = physics_estimate([mask(0), mask(1)], &blind).unwrap();
            let error = (estimate.fit.force_n - sample.params.tip_force_n).max_abs();
            assert!(error < 0.03, "{index}: force off by {error} N");
            assert!(estimate.fit.rms_mm < 0.1, "{}", estimate.fit.rms_mm);
            let base_error =
                (estimate.fit.base.position_mm - sample.params.base_position_mm).norm();
            assert!(base_error < 0.5, "{index}: base off by {base_error} mm");
            let weighed = if estimate.reconstruction.tip_seen {
                TipUse::Weighed
            } else {
                TipUse::NotWeighed
            };
            assert_eq!(estimate.tip, weighed, "{index}");
        }
        // A catalogue entry 5 mm shorter than the catheter (the mismatch suite's `length+5mm`):
        // its rod reaches the seen tip only with the base pulled beyond the fixture's play, so
        // the tip is set aside and the shape read without it.
        let (config, sample) = bench_sample(128, 11, 1);
        let short = CatalogueCatheter {
            flexible_length_mm: catheter.flexible_length_mm - 5.0,
            ..catheter.clone()
        };
        let cameras = [
            config.views.a.camera_matrix(),
            config.views.b.camera_matrix(),
        ];
        let mask = |i: usize| Mask::coverage8(128, 128, &sample.views[i].mask);
        let estimate = physics_estimate(
            [mask(0), mask(1)],
            &PhysicsSetup::blind(cameras, &short, &nominal),
        )
        .unwrap();
        assert_eq!(estimate.tip, TipUse::SetAside);
        // A catalogue entry 5 mm longer than the catheter: the rod may run on past the seen tip
        // by that much (`MAX_ROD_BEYOND_SEEN_TIP_MM`), so it is not refused for it.
        let long_by_5 = CatalogueCatheter {
            flexible_length_mm: catheter.flexible_length_mm + 5.0,
            ..catheter.clone()
        };
        let read = physics_estimate(
            [mask(0), mask(1)],
            &PhysicsSetup::blind(cameras, &long_by_5, &nominal),
        )
        .unwrap();
        assert_eq!(read.tip, TipUse::SetAside);
        let seen_tip = read.reconstruction.points_mm[read.reconstruction.points_mm.len() - 1];
        let beyond_mm = rod_beyond_mm(&read.fit.shape, seen_tip);
        assert!(
            (1.0..=MAX_ROD_BEYOND_SEEN_TIP_MM).contains(&beyond_mm),
            "{beyond_mm} mm"
        );
        // A catheter the masks do not show (twice as long): it fits only with its base far
        // beyond the fixture's play, or by running on past the seen tip, and no force is given.
        let (config, sample) = bench_sample(128, 11, 0);
        let long = CatalogueCatheter {
            flexible_length_mm: 100.0,
            ..catheter
        };
        let setup = PhysicsSetup::blind(
            [
                config.views.a.camera_matrix(),
                config.views.b.camera_matrix(),
            ],
            &long,
            &nominal,
        );
        let mask = |i: usize| Mask::coverage8(128, 128, &sample.views[i].mask);
        match physics_estimate([mask(0), mask(1)], &setup) {
            Err(PhysicsError::BaseOutsideTolerance { offset_mm, .. }) => {
                assert!(offset_mm > 10.0, "{offset_mm}")
            }
            Err(PhysicsError::RodBeyondSeenTip { beyond_mm }) => {
                assert!(beyond_mm > 40.0, "{beyond_mm}")
            }
            Err(other) => panic!("{other}"),
            Ok(e) => panic!(
                "a 100 mm rod fitted a 50 mm catheter within {} mm",
                e.fit.rms_mm
            ),
        }
    }
}
