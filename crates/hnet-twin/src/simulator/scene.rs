//! One stereo sample of the twin: sampled mechanics, the solved catheter and both rendered views
//! with their exact masks.
//!
//! Every random choice of sample `index` comes from its own generator seeded by `(seed, index)`,
//! so samples can be generated in any order or in parallel and still be identical.

use hnet_units::TipForce;
use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

use crate::reconstruction::rod_fit::{BasePrior, PRIOR_CORRELATED_POINTS};
use crate::simulator::rod::{self, RodBase, RodConfig, RodError, StiffSegment};
use crate::simulator::sensor_plate::{PlateContact, SensorPlate};
use crate::vec3::{Mat3, Vec3};

mod ranges;
mod sample;
pub use sample::{
    Backgrounds, MaskRecipe, PHANTOM_SIDE_PX, StereoSample, TwinConfig, TwinError, ViewPixels,
    ViewSample, XRayRecipe, generate, luma, otsu_threshold, render_empty_xray_view, render_view,
    sample_rng, threshold_mask,
};

/// What the images look like.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Modality {
    /// The paper's bench: two colour cameras.
    Rgb,
    /// Synthetic X-ray on consistently bright patches (easy).
    Xray1,
    /// Synthetic X-ray on mixed dark and bright patches (hard).
    Xray2,
}

impl Modality {
    /// The name used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Modality::Rgb => "rgb",
            Modality::Xray1 => "xray1",
            Modality::Xray2 => "xray2",
        }
    }

    /// Parses `rgb`, `xray1` or `xray2`.
    pub fn parse(name: &str) -> Option<Self> {
        [Modality::Rgb, Modality::Xray1, Modality::Xray2]
            .into_iter()
            .find(|m| m.name() == name)
    }

    /// Whether the images are X-ray frames (grey) rather than camera photographs (colour).
    pub fn is_xray(self) -> bool {
        self != Modality::Rgb
    }
}

/// How scenes are drawn: the tip force, the catheter and its base pose. Three presets:
///
/// - [`SceneSampling::bench`] (the default): the paper's bench. One catheter (7 Fr, EI 0.6 x
///   10⁻³ N·m², 50 mm flexible, pre-curved to a 60 mm radius), its base clamped 35 mm caudal of
///   the isocentre pointing cranially (within 1 mm and 2°, the fixture's play), and a random tip
///   force. The shape then depends on the force alone, as on the bench the paper recorded.
/// - [`SceneSampling::varied`]: domain randomisation over catheters and poses: bending stiffness
///   0.4-0.9 x 10⁻³ N·m², flexible length 40-60 mm, pre-curvature up to 1/35 mm⁻¹ in a random
///   plane, the base moved by up to 6 mm and tilted by up to 25°. The same shape can then come
///   from different forces (a stiffer catheter bends less), so force from images is ambiguous.
///
/// In both, tip forces are of clinical size: uniform in magnitude up to 0.4 N, pointing back
/// against the catheter within 80° of its base axis (a contact force).
///
/// - [`SceneSampling::paper_bench`]: the bench as the paper recorded it, framed close up
///   ([`TwinConfig::paper_bench`]): the same catheter and fixture, its tip pressed against a
///   sensor plate moved by two actuators ([`crate::simulator::sensor_plate`]). The force is not drawn: it
///   is read from the rod solved with its tip held by the plate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSampling {
    /// Range of the tip force magnitude, N.
    pub force_magnitude_n: [f64; 2],
    /// Largest angle between the force and the direction opposing the base axis, degrees.
    pub force_cone_deg: f64,
    /// Range of the bending stiffness EI, N·m².
    pub bending_stiffness_n_m2: [f64; 2],
    /// Range of the flexible length, mm.
    pub length_mm: [f64; 2],
    /// Range of the intrinsic curvature, 1/mm.
    pub precurvature_per_mm: [f64; 2],
    /// Nominal base position, mm.
    pub base_position_mm: Vec3,
    /// Largest shift of the base along each axis, mm.
    pub base_jitter_mm: f64,
    /// Largest tilt of the base axis away from +z (cranial), degrees.
    pub base_tilt_deg: f64,
    /// Range of the rotation of the section about the base axis (the pre-curve's plane),
    /// degrees.
    pub base_roll_deg: [f64; 2],
    /// Largest shift of the catheter along each axis between the two planes' exposures, mm:
    /// view B sees it moved by a uniform draw within ± this (biplane planes expose in turn,
    /// tens of milliseconds apart, while the heart and breathing move the catheter). 0 (both
    /// views at one instant) unless set; the record keeps view A's instant.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub exposure_motion_mm: f64,
    /// The sensor plate the tip is pressed against, when the force comes from a contact (the
    /// paper's bench): then `force_magnitude_n` and `force_cone_deg` only say what range of
    /// forces the actuators' travel produces (for [`Self::departures`]), nothing is drawn from
    /// them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plate: Option<SensorPlate>,
    /// The fixture's axis leant away from cranial: the nominal pose the base's jitter and tilt
    /// are drawn about. None (the default): cranial.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_lean: Option<BaseLean>,
    /// How much stiffer than the shaft the tip electrode is over its length (the catheter
    /// design's `tip_electrode_mm`): a platinum-iridium shell. 1 (the default, what every
    /// estimate assumes): the shaft's stiffness to the tip.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub tip_electrode_stiffness: f64,
    /// The catheter leaves a sheath rather than a clamp. None (the default, what every estimate
    /// assumes): clamped at the base.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sheath: Option<Sheath>,
    /// The tip force acts where the tip's rounded electrode touches a wall, with this Coulomb
    /// friction coefficient, instead of on the centreline's end: a tip moment. None (the
    /// default, what every estimate assumes): no tip moment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_friction: Option<f64>,
}

/// A lean of the fixture's axis: `tilt_deg` away from cranial (+z), the tilt turned
/// `azimuth_deg` about z. Tilt 0 leans nowhere; azimuth 0 leans towards -y, the source of the
/// frontal C-arm (`CArm::cardiac(0, 0, _)`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BaseLean {
    /// Degrees from cranial.
    pub tilt_deg: f64,
    /// Degrees about z.
    pub azimuth_deg: f64,
}

impl BaseLean {
    /// The rotation taking the cranial axis to the leant one.
    pub fn rotation(&self) -> Mat3 {
        Mat3::rotation(Vec3::Z, self.azimuth_deg.to_radians())
            * Mat3::rotation(Vec3::X, self.tilt_deg.to_radians())
    }
}

/// A sheath the catheter runs through: its last `free_length_mm` stand free of whatever holds
/// it (a septum, a vessel), and the catheter inside makes that stretch `stiffness_factor` times
/// as stiff as the catheter alone. The base the estimates assume is the sheath's end at rest;
/// under load it moves and turns.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sheath {
    /// Free length, mm.
    pub free_length_mm: f64,
    /// Stiffness of sheath and catheter together over the catheter's.
    pub stiffness_factor: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn one() -> f64 {
    1.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

impl Default for SceneSampling {
    fn default() -> Self {
        Self::bench()
    }
}

impl SceneSampling {
    /// The paper's bench: one catheter on a fixed base, a random tip force.
    pub fn bench() -> Self {
        Self {
            force_magnitude_n: [0.0, 0.4],
            force_cone_deg: 80.0,
            bending_stiffness_n_m2: [0.6e-3, 0.6e-3],
            length_mm: [50.0, 50.0],
            precurvature_per_mm: [1.0 / 60.0, 1.0 / 60.0],
            base_position_mm: Vec3::new(0.0, 0.0, -35.0),
            base_jitter_mm: 1.0,
            base_tilt_deg: 2.0,
            base_roll_deg: [90.0, 90.0],
            exposure_motion_mm: 0.0,
            plate: None,
            base_lean: None,
            tip_electrode_stiffness: 1.0,
            sheath: None,
            contact_friction: None,
        }
    }

    /// The paper's bench: the bench's catheter and fixture, placed so that the flexible section
    /// is centred in the close-up cameras' frame, its tip pressed against the sensor plate
    /// ([`SensorPlate::bench`]). The actuators' travel gives tip forces up to about 0.6 N
    /// (docs/twin.md, "The paper's bench").
    pub fn paper_bench() -> Self {
        Self {
            force_magnitude_n: [0.0, 0.6],
            force_cone_deg: 180.0,
            base_position_mm: Vec3::new(-10.0, 0.0, -22.0),
            plate: Some(SensorPlate::bench()),
            ..Self::bench()
        }
    }

    /// Domain randomisation over catheters and base poses.
    pub fn varied() -> Self {
        Self {
            bending_stiffness_n_m2: [0.4e-3, 0.9e-3],
            length_mm: [40.0, 60.0],
            precurvature_per_mm: [0.0, 1.0 / 35.0],
            base_jitter_mm: 6.0,
            base_tilt_deg: 25.0,
            base_roll_deg: [0.0, 360.0],
            ..Self::bench()
        }
    }

    /// The base pose a user of these scenes knows without the pair's own record: the nominal
    /// position, pointing cranially (no tilt), the section rolled to the middle of the roll
    /// range (for the bench, the fixture's pre-curve plane), and how far the base may be from it
    /// (the jitter's and the tilt's spread as standard deviations; the roll about the axis free).
    /// A blind estimate starts its base fit here and keeps near it unless the shape says
    /// otherwise.
    pub fn nominal_base(&self) -> NominalBase {
        let nominal = self.nominal_scene();
        // A uniform draw within ±j has a standard deviation of j/√3; a tilt uniform over a cap
        // of half-angle t about t/√2 per component. Floors keep a fixed fixture from pinning
        // the fit (its play is never zero). The roll is left free: `base_frame` turns the
        // section by the tilt's azimuth too, so the pre-curve's plane is uniform about the axis
        // in every preset, the bench's included (docs/twin.md, "The base pose").
        NominalBase {
            base: RodBase {
                position_mm: nominal.base_position_mm,
                orientation: nominal.base_frame(),
            },
            tolerance: BasePrior {
                position_sd_mm: (self.base_jitter_mm / 3f64.sqrt()).max(0.25),
                tilt_sd_deg: (self.base_tilt_deg / 2f64.sqrt()).max(0.5),
                roll_sd_deg: None,
                correlated_points: PRIOR_CORRELATED_POINTS,
            },
        }
    }

    /// The unloaded scene at the nominal pose: the lower end of each catheter range, the nominal
    /// base pointing cranially, the roll at the middle of its range (see [`Self::nominal_base`]).
    pub fn nominal_scene(&self) -> SceneParams {
        let mut scene = SceneParams {
            tip_force_n: TipForce::ZERO,
            bending_stiffness_n_m2: self.bending_stiffness_n_m2[0],
            length_mm: self.length_mm[0],
            precurvature_per_mm: self.precurvature_per_mm[0],
            base_position_mm: self.base_position_mm,
            base_tilt_deg: 0.0,
            base_azimuth_deg: 0.0,
            base_roll_deg: 0.5 * (self.base_roll_deg[0] + self.base_roll_deg[1]),
            plate: None,
            wall_normal: None,
        };
        if let Some(lean) = self.base_lean {
            scene.set_base_frame(lean.rotation() * scene.base_frame());
        }
        scene
    }

    /// The names [`Self::preset`] takes.
    pub const PRESETS: [&'static str; 3] = ["bench", "varied", PAPER_BENCH];

    /// A preset by name: `bench`, `varied` or `paper-bench`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "bench" => Some(Self::bench()),
            "varied" => Some(Self::varied()),
            PAPER_BENCH => Some(Self::paper_bench()),
            _ => None,
        }
    }
}

/// The name of the paper's bench preset (scenes, views and X-ray recipe together:
/// [`TwinConfig::paper_bench`]).
pub const PAPER_BENCH: &str = "paper-bench";

/// Where a catheter's base is expected before its images are read, and how far off it may be.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NominalBase {
    /// The nominal pose.
    pub base: RodBase,
    /// How far the true base may be from it.
    pub tolerance: BasePrior,
}

/// The drawn parameters of one scene. Forces are in the world frame, newtons.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneParams {
    /// Tip force `(Fx, Fy, Fz)`, N (x: patient left, y: anterior, z: cranial).
    pub tip_force_n: TipForce,
    /// Bending stiffness EI, N·m².
    pub bending_stiffness_n_m2: f64,
    /// Flexible length, mm.
    pub length_mm: f64,
    /// Intrinsic curvature about the section's x axis, 1/mm.
    pub precurvature_per_mm: f64,
    /// Base position, mm.
    pub base_position_mm: Vec3,
    /// Tilt of the base axis from +z, degrees.
    pub base_tilt_deg: f64,
    /// Direction of that tilt around z, degrees.
    pub base_azimuth_deg: f64,
    /// Rotation of the section about the base axis (sets the pre-curve's plane), degrees.
    pub base_roll_deg: f64,
    /// The sensor plate's actuator positions and the contact they made, when the force comes
    /// from pressing the tip against it (the paper's bench).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plate: Option<PlateContact>,
    /// The outward normal of the wall the tip presses on, when the force acts where the tip's
    /// rounded electrode touches it ([`SceneSampling::contact_friction`]), world frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_normal: Option<Vec3>,
}

impl SceneParams {
    /// The base frame: rolled about its axis, tilted away from +z, and the tilt turned to its
    /// azimuth about z.
    pub fn base_frame(&self) -> Mat3 {
        Mat3::rotation(Vec3::Z, self.base_azimuth_deg.to_radians())
            * Mat3::rotation(Vec3::X, self.base_tilt_deg.to_radians())
            * Mat3::rotation(Vec3::Z, self.base_roll_deg.to_radians())
    }

    /// Sets the base's tilt, azimuth and roll to those of the rotation `frame` (its z-x-z
    /// Euler angles, as [`Self::base_frame`] composes them).
    pub fn set_base_frame(&mut self, frame: Mat3) {
        let m = frame.0;
        let tilt = m[2][2].clamp(-1.0, 1.0).acos();
        if tilt.sin() < 1e-12 {
            // About the z axis only (or turned over): the tilt's azimuth and the roll are one
            // turn, taken as the roll.
            self.base_azimuth_deg = 0.0;
            let roll = if m[2][2] > 0.0 {
                m[1][0].atan2(m[0][0])
            } else {
                (-m[1][0]).atan2(m[0][0])
            };
            self.base_roll_deg = roll.to_degrees();
        } else {
            self.base_azimuth_deg = m[0][2].atan2(-m[1][2]).to_degrees();
            self.base_roll_deg = m[2][0].atan2(m[2][1]).to_degrees();
        }
        self.base_tilt_deg = tilt.to_degrees();
    }

    /// The rod to solve: `template` with this scene's length, stiffness and pre-curvature.
    pub fn rod(&self, template: &RodConfig) -> (RodConfig, RodBase) {
        let config = RodConfig {
            length_mm: self.length_mm,
            precurvature_per_mm: [self.precurvature_per_mm, 0.0],
            ..template.clone()
        }
        .with_bending_stiffness(self.bending_stiffness_n_m2 * 1e6);
        let base = RodBase {
            position_mm: self.base_position_mm,
            orientation: self.base_frame(),
        };
        (config, base)
    }
}

fn uniform(rng: &mut impl Rng, range: [f64; 2]) -> f64 {
    range[0] + (range[1] - range[0]) * rng.random::<f64>()
}

impl SceneSampling {
    /// Draws one scene.
    pub fn sample(&self, rng: &mut impl Rng) -> SceneParams {
        let mut jitter = || self.base_jitter_mm * (2.0 * rng.random::<f64>() - 1.0);
        let base_position_mm = self.base_position_mm + Vec3::new(jitter(), jitter(), jitter());
        // Uniform over the spherical cap of the tilt cone.
        let cos_tilt = 1.0 - (1.0 - self.base_tilt_deg.to_radians().cos()) * rng.random::<f64>();
        let base_tilt_deg = cos_tilt.acos().to_degrees();
        let base_azimuth_deg = 360.0 * rng.random::<f64>();
        let base_roll_deg = uniform(rng, self.base_roll_deg);
        let mut params = SceneParams {
            tip_force_n: TipForce::ZERO,
            bending_stiffness_n_m2: uniform(rng, self.bending_stiffness_n_m2),
            length_mm: uniform(rng, self.length_mm),
            precurvature_per_mm: uniform(rng, self.precurvature_per_mm),
            base_position_mm,
            base_tilt_deg,
            base_azimuth_deg,
            base_roll_deg,
            plate: None,
            wall_normal: None,
        };
        if let Some(lean) = self.base_lean {
            params.set_base_frame(lean.rotation() * params.base_frame());
        }
        // Pressed against a plate: the actuators are drawn, the force is solved for later.
        // The fixture holds the pre-curve's plane where the bench put it: the roll is counted
        // from the tilt's azimuth (`base_frame` turns the section by both).
        if let Some(plate) = &self.plate {
            params.base_roll_deg -= base_azimuth_deg;
            params.plate = Some(plate.draw(rng));
            return params;
        }
        // The force: uniform direction within the cone around -axis, uniform magnitude.
        let axis = params.base_frame().column(2);
        let cos_cone = self.force_cone_deg.to_radians().cos();
        let cos_theta = 1.0 - (1.0 - cos_cone) * rng.random::<f64>();
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = std::f64::consts::TAU * rng.random::<f64>();
        let e1 = axis.any_perpendicular();
        let e2 = axis.cross(e1);
        let direction = -axis * cos_theta + (e1 * phi.cos() + e2 * phi.sin()) * sin_theta;
        params.tip_force_n = (direction * uniform(rng, self.force_magnitude_n)).into();
        // A wall whose normal lies within the friction cone about the force (Coulomb: the
        // tangential part at most μ times the normal part), drawn only for such sets so that
        // the others keep their draws.
        if let Some(friction) = self.contact_friction {
            let angle = friction.atan() * rng.random::<f64>();
            let phi = std::f64::consts::TAU * rng.random::<f64>();
            let e1 = direction.any_perpendicular();
            let e2 = direction.cross(e1);
            let across = e1 * phi.cos() + e2 * phi.sin();
            params.wall_normal = Some(direction * angle.cos() + across * angle.sin());
        }
        params
    }

    /// The rod as simulated, with what the estimates do not model (the tip electrode's
    /// stiffness, the sheath, the contact on the tip's surface) added to `rod` and `base`, the
    /// clamped rod of [`SceneParams::rod`]. Also returns the sheath's free length (mm), the arc
    /// length where the catheter's flexible section begins (0 without a sheath).
    pub fn rod_as_simulated(
        &self,
        scene: &SceneParams,
        rod: RodConfig,
        base: RodBase,
        tip_electrode_mm: f64,
    ) -> Result<(RodConfig, RodBase, f64), RodError> {
        let (mut rod, mut base) = (rod, base);
        let mut sheath_mm = 0.0;
        if let Some(sheath) = self.sheath.filter(|sheath| sheath.free_length_mm > 0.0) {
            // A whole number of the flexible section's steps, so that the sheath's end is a
            // point of the solved centreline and its stiffness ends on a step.
            let step_mm = rod.length_mm / rod.steps as f64;
            let sheath_steps = (sheath.free_length_mm / step_mm).round().max(1.0) as usize;
            sheath_mm = sheath_steps as f64 * step_mm;
            base.position_mm = base.position_mm - base.orientation.column(2) * sheath_mm;
            rod.length_mm += sheath_mm;
            rod.precurve_start_mm += sheath_mm;
            rod.steps += sheath_steps;
            for segment in &mut rod.stiff_segments {
                segment.from_mm += sheath_mm;
                segment.to_mm += sheath_mm;
            }
            rod.stiff_segments.push(StiffSegment {
                from_mm: 0.0,
                to_mm: sheath_mm,
                factor: sheath.stiffness_factor,
            });
        }
        if self.tip_electrode_stiffness != 1.0 && tip_electrode_mm > 0.0 {
            let length = rod.length_mm;
            rod.stiff_segments.push(StiffSegment {
                from_mm: (length - tip_electrode_mm).max(sheath_mm),
                to_mm: length,
                factor: self.tip_electrode_stiffness,
            });
        }
        if let Some(wall_normal) = scene.wall_normal {
            // The contact sits where the unloaded tip's rounded end first touched the wall (the
            // point whose outward normal faces it), and stays there on the electrode as the
            // load builds (friction holds it).
            let frame = rod::rest_tip_frame(&rod, &base)?;
            let radius = 0.5 * rod.diameter_mm;
            let facing = frame.transpose() * -wall_normal.normalized();
            // On the dome (the half facing forwards), else on its rim.
            let on_surface = if facing.z() >= 0.0 {
                facing
            } else {
                Vec3::new(facing.x(), facing.y(), 0.0).normalized()
            };
            rod.tip_load_offset_mm = (on_surface - Vec3::Z) * radius;
        }
        Ok((rod, base, sheath_mm))
    }
}

#[cfg(test)]
mod tests {
    use super::sample::grey_of;
    use super::*;
    use crate::simulator::render::XRayDetector;
    use crate::simulator::sensor_plate;
    use hnet_units::ImageSize;
    use hnet_units::mask::is_catheter_label;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn motion_between_exposures_moves_the_catheter_in_view_b_only() {
        let mut config = TwinConfig::new(Modality::Xray2, ImageSize::square(64));
        let backgrounds = Backgrounds::phantom(&config.views);
        let still = generate(&config, &backgrounds, 7, 3).unwrap();
        config.scene.exposure_motion_mm = 1.0;
        let moved = generate(&config, &backgrounds, 7, 3).unwrap();
        assert_eq!(still.params, moved.params);
        assert_eq!(still.views[0].mask, moved.views[0].mask);
        assert_ne!(still.views[1].mask, moved.views[1].mask);
        config.scene.exposure_motion_mm = -1.0;
        assert!(
            config
                .scene
                .check()
                .unwrap_err()
                .contains("exposure_motion_mm")
        );
    }

    #[test]
    fn scatter_lowers_the_catheters_contrast_and_leaves_its_mask() {
        let mut config = TwinConfig::new(Modality::Xray2, ImageSize::square(64));
        let backgrounds = Backgrounds::phantom(&config.views);
        let plain = generate(&config, &backgrounds, 7, 3).unwrap();
        config.detector.scatter_fraction = 0.3;
        let veiled = generate(&config, &backgrounds, 7, 3).unwrap();
        // Mean grey of the background minus that of the catheter, view A.
        let contrast = |s: &StereoSample| {
            let ViewPixels::Grey(grey) = &s.views[0].pixels else {
                panic!("an X-ray view is grey")
            };
            let (mut sums, mut counts) = ([0.0f64; 2], [0usize; 2]);
            for (&g, &m) in grey.iter().zip(&s.views[0].mask) {
                let i = usize::from(is_catheter_label(m));
                sums[i] += f64::from(g);
                counts[i] += 1;
            }
            sums[0] / counts[0] as f64 - sums[1] / counts[1] as f64
        };
        assert_eq!(plain.views[0].mask, veiled.views[0].mask);
        assert!(
            contrast(&veiled) < 0.9 * contrast(&plain),
            "{} vs {}",
            contrast(&veiled),
            contrast(&plain)
        );
        let refused = XRayDetector {
            scatter_fraction: 1.0,
            ..XRayDetector::default()
        };
        assert!(refused.check().unwrap_err().contains("scatter_fraction"));
    }

    #[test]
    fn the_papers_bench_frames_the_section_close_up_and_pastes_its_thresholded_catheter() {
        let mut config = TwinConfig::paper_bench(Modality::Xray2, ImageSize::square(96));
        let backgrounds = Backgrounds::phantom(&config.views);
        let pasted = generate(&config, &backgrounds, 5, 1).unwrap();
        let contact = pasted.params.plate.expect("the force comes from the plate");
        assert_ne!(contact.state, sensor_plate::ContactState::Free);
        assert!(pasted.params.tip_force_n.magnitude() > 0.0);
        config.mask = MaskRecipe::Geometry;
        let exact = generate(&config, &backgrounds, 5, 1).unwrap();
        assert_eq!(pasted.params, exact.params);
        for (cut, view) in pasted.views.iter().zip(&exact.views) {
            // The thresholded catheter is the exact one, give or take its edges and highlights.
            let inside = |m: &[u8], i: usize| is_catheter_label(m[i]);
            let (mut both, mut either) = (0, 0);
            for i in 0..cut.mask.len() {
                both += usize::from(inside(&cut.mask, i) && inside(&view.mask, i));
                either += usize::from(inside(&cut.mask, i) || inside(&view.mask, i));
            }
            let iou = both as f64 / either as f64;
            assert!(iou > 0.8, "IoU {iou}");
            // The same frame either way: the mask is a label, not part of the recipe.
            assert_eq!(cut.pixels, view.pixels);
        }
        // Close up: the section spans most of view A's height.
        let rows: Vec<usize> = (0..96)
            .filter(|&r| {
                exact.views[0].mask[r * 96..(r + 1) * 96]
                    .iter()
                    .any(|&m| is_catheter_label(m))
            })
            .collect();
        assert!(rows.len() > 96 * 6 / 10, "{} rows", rows.len());
    }

    #[test]
    fn the_same_seed_and_index_give_the_same_sample() {
        let config = TwinConfig::new(Modality::Xray2, ImageSize::square(64));
        let backgrounds = Backgrounds::phantom(&config.views);
        let a = generate(&config, &backgrounds, 7, 3).unwrap();
        let b = generate(&config, &backgrounds, 7, 3).unwrap();
        assert_eq!(a, b);
        let c = generate(&config, &backgrounds, 7, 4).unwrap();
        assert_ne!(a.params, c.params);
    }

    #[test]
    fn sampled_forces_are_of_clinical_size_and_push_back_on_the_tip() {
        for (sampling, tilt) in [
            (SceneSampling::bench(), 2.0),
            (SceneSampling::varied(), 25.0),
        ] {
            let mut rng = sample_rng(1, 0);
            for _ in 0..500 {
                let p = sampling.sample(&mut rng);
                let f = Vec3::from(p.tip_force_n).norm();
                assert!(f <= 0.4 + 1e-12);
                let axis = p.base_frame().column(2);
                if f > 1e-9 {
                    let angle = (-Vec3::from(p.tip_force_n).dot(axis) / f)
                        .acos()
                        .to_degrees();
                    assert!(angle <= 80.0 + 1e-9, "{angle}");
                }
                assert!(p.base_tilt_deg <= tilt + 1e-9);
                assert!((0.4e-3..=0.9e-3).contains(&p.bending_stiffness_n_m2));
                assert!((40.0..=60.0).contains(&p.length_mm));
            }
        }
    }

    #[test]
    fn drawn_scenes_are_inside_their_sampling_and_others_are_named() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for sampling in [SceneSampling::bench(), SceneSampling::varied()] {
            for _ in 0..200 {
                let scene = sampling.sample(&mut rng);
                assert_eq!(
                    sampling.departures(&scene),
                    Vec::<String>::new(),
                    "{scene:?}"
                );
            }
        }
        let bench = SceneSampling::bench();
        let mut scene = bench.sample(&mut rng);
        scene.tip_force_n = TipForce::new(0.6, 0.0, 0.3);
        scene.bending_stiffness_n_m2 = 0.3e-3;
        let departures = bench.departures(&scene);
        assert_eq!(departures.len(), 3, "{departures:?}");
        assert!(
            departures[0].starts_with("|F| 0.67 N (trained on 0.00-0.40 N)"),
            "{departures:?}"
        );
        assert!(
            departures[1].starts_with("the force points"),
            "{departures:?}"
        );
        assert_eq!(
            departures[2],
            "stiffness EI 0.30 mN·m² (trained on 0.60 mN·m²)"
        );
    }

    #[test]
    fn the_bench_varies_only_the_force_and_the_fixtures_play() {
        let sampling = SceneSampling::bench();
        let mut rng = sample_rng(2, 0);
        let nominal = sampling.base_position_mm;
        let draws: Vec<SceneParams> = (0..100).map(|_| sampling.sample(&mut rng)).collect();
        for p in &draws {
            assert_eq!(p.bending_stiffness_n_m2, 0.6e-3);
            assert_eq!(p.length_mm, 50.0);
            assert_eq!(p.base_roll_deg, 90.0);
            assert!((p.base_position_mm - nominal).norm() <= 3f64.sqrt() + 1e-9);
        }
        let distinct =
            |f: fn(&SceneParams) -> f64| draws.windows(2).filter(|w| f(&w[0]) != f(&w[1])).count();
        assert_eq!(distinct(|p| f64::from(p.tip_force_n.x())), 99);
        assert_eq!(
            SceneSampling::preset("varied"),
            Some(SceneSampling::varied())
        );
        assert_eq!(SceneSampling::preset("other"), None);
    }

    #[test]
    fn unmodelled_mechanics_and_a_leant_fixture_change_the_catheter_as_set() {
        // The base's angles read back from its frame.
        let mut scene = SceneSampling::bench().nominal_scene();
        for (tilt, azimuth, roll) in [
            (0.0, 0.0, 30.0),
            (45.0, 0.0, 90.0),
            (20.0, 130.0, -60.0),
            (170.0, -40.0, 10.0),
        ] {
            (
                scene.base_tilt_deg,
                scene.base_azimuth_deg,
                scene.base_roll_deg,
            ) = (tilt, azimuth, roll);
            let mut read = scene;
            read.set_base_frame(scene.base_frame());
            let (a, b) = (scene.base_frame().0, read.base_frame().0);
            assert!(
                (0..9).all(|i| (a[i / 3][i % 3] - b[i / 3][i % 3]).abs() < 1e-9),
                "{tilt} {azimuth} {roll}"
            );
        }
        // Leant 45° towards the frontal C-arm's source (-y); its draws are its own.
        let leant = SceneSampling {
            base_lean: Some(BaseLean {
                tilt_deg: 45.0,
                azimuth_deg: 0.0,
            }),
            ..SceneSampling::bench()
        };
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let axis = leant.nominal_scene().base_frame().column(2);
        assert!(
            (axis - Vec3::new(0.0, -half, half)).norm() < 1e-9,
            "{axis:?}"
        );
        let drawn = leant.sample(&mut sample_rng(3, 0));
        assert!(leant.departures(&drawn).is_empty());
        assert!(!SceneSampling::bench().departures(&drawn).is_empty());

        let mut config = TwinConfig::new(Modality::Xray2, ImageSize::square(64));
        let backgrounds = Backgrounds::phantom(&config.views);
        let plain = generate(&config, &backgrounds, 7, 3).unwrap();
        let flexible = |s: &StereoSample| *s.shape.arc_mm.last().unwrap();
        let with = |config: &mut TwinConfig, scene: SceneSampling| {
            config.scene = scene;
            generate(config, &backgrounds, 7, 3).unwrap()
        };
        // A rigid tip electrode: the same draw, another shape.
        let rigid = with(
            &mut config,
            SceneSampling {
                tip_electrode_stiffness: 50.0,
                ..SceneSampling::bench()
            },
        );
        assert_eq!(rigid.params, plain.params);
        // (This pair's force is 0.03 N: the tip moves by about 0.6 µm.)
        assert!((rigid.shape.tip_mm() - plain.shape.tip_mm()).norm() > 1e-4);
        // A sheath: its end (the record's base) moves under the load; the record keeps the
        // flexible section, the views show the sheath too.
        let sheathed = with(
            &mut config,
            SceneSampling {
                sheath: Some(Sheath {
                    free_length_mm: 20.0,
                    stiffness_factor: 4.0,
                }),
                ..SceneSampling::bench()
            },
        );
        assert_eq!(sheathed.params, plain.params);
        assert!((flexible(&sheathed) - flexible(&plain)).abs() < 1e-6);
        let moved = (sheathed.shape.points_mm[0] - plain.shape.points_mm[0]).norm();
        assert!(
            moved > 1e-3 && moved < 10.0,
            "the sheath's end moved {moved} mm"
        );
        assert_ne!(sheathed.views[0].mask, plain.views[0].mask);
        // A contact on the tip's surface: the wall within the friction cone, the same force.
        let touching = with(
            &mut config,
            SceneSampling {
                contact_friction: Some(0.3),
                ..SceneSampling::bench()
            },
        );
        assert_eq!(touching.params.tip_force_n, plain.params.tip_force_n);
        let wall = touching.params.wall_normal.unwrap();
        let force = Vec3::from(touching.params.tip_force_n).normalized();
        assert!(wall.dot(force).clamp(-1.0, 1.0).acos() <= 0.3f64.atan() + 1e-9);
        assert!((touching.shape.tip_mm() - plain.shape.tip_mm()).norm() > 1e-4);
        // Settings that cannot be are refused by name.
        for (scene, name) in [
            (
                SceneSampling {
                    tip_electrode_stiffness: 0.0,
                    ..SceneSampling::bench()
                },
                "tip_electrode_stiffness",
            ),
            (
                SceneSampling {
                    contact_friction: Some(-1.0),
                    ..SceneSampling::bench()
                },
                "contact_friction",
            ),
            (
                SceneSampling {
                    contact_friction: Some(0.3),
                    ..SceneSampling::paper_bench()
                },
                "contact_friction",
            ),
        ] {
            assert!(scene.check().unwrap_err().contains(name), "{name}");
        }
    }

    #[test]
    fn masks_match_the_catheter_in_the_images() {
        for modality in [Modality::Rgb, Modality::Xray1] {
            let config = TwinConfig::new(modality, ImageSize::square(96));
            let backgrounds = Backgrounds::phantom(&config.views);
            let sample = generate(&config, &backgrounds, 11, 0).unwrap();
            for view in &sample.views {
                let grey = grey_of(&view.pixels);
                let (mut inside, mut n_in, mut outside, mut n_out) = (0.0, 0, 0.0, 0);
                for (g, m) in grey.iter().zip(&view.mask) {
                    if *m >= 200 {
                        inside += f64::from(*g);
                        n_in += 1;
                    } else if *m == 0 {
                        outside += f64::from(*g);
                        n_out += 1;
                    }
                }
                assert!(n_in > 50, "{modality:?}: mask too small ({n_in} px)");
                // The catheter is darker than what surrounds it.
                assert!(
                    inside / n_in as f64 + 15.0 < outside / n_out as f64,
                    "{modality:?}: catheter {} vs background {}",
                    inside / n_in as f64,
                    outside / n_out as f64
                );
            }
        }
    }

    #[test]
    fn otsu_separates_two_levels() {
        let grey: Vec<u8> = (0..100).map(|i| if i < 30 { 40 } else { 200 }).collect();
        let t = otsu_threshold(&grey);
        assert!((40..200).contains(&t));
        let mask = threshold_mask(&grey, t);
        assert_eq!(mask.iter().filter(|&&m| m == 255).count(), 30);
    }
}
