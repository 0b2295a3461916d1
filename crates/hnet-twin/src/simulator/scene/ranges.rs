//! What a scene sampling allows and how a scene departs from it: [`SceneSampling::check`]
//! refuses settings that cannot be drawn from; [`SceneSampling::departures`] and
//! [`SceneSampling::catheter_departures`] name where a scene's force, catheter or pose lies
//! outside them. Part of [`crate::simulator::scene`].

use super::*;

impl SceneSampling {
    /// Why these settings cannot be drawn from, if they cannot: a range whose ends are not
    /// finite or are reversed, a negative force, a cone outside 0-180°, a length or stiffness
    /// that is not positive, a negative jitter or tilt.
    pub fn check(&self) -> Result<(), String> {
        let ranges = [
            ("force_magnitude_n", self.force_magnitude_n),
            ("bending_stiffness_n_m2", self.bending_stiffness_n_m2),
            ("length_mm", self.length_mm),
            ("precurvature_per_mm", self.precurvature_per_mm),
            ("base_roll_deg", self.base_roll_deg),
        ];
        for (name, [lo, hi]) in ranges {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(format!(
                    "{name} must be a range [low, high] of finite numbers, low ≤ high"
                ));
            }
        }
        let in_range = [
            ("force_magnitude_n", self.force_magnitude_n[0] >= 0.0),
            (
                "bending_stiffness_n_m2",
                self.bending_stiffness_n_m2[0] > 0.0,
            ),
            ("length_mm", self.length_mm[0] > 0.0),
            ("base_jitter_mm", self.base_jitter_mm >= 0.0),
            (
                "exposure_motion_mm",
                (0.0..=20.0).contains(&self.exposure_motion_mm),
            ),
            ("base_tilt_deg", (0.0..=90.0).contains(&self.base_tilt_deg)),
            (
                "force_cone_deg",
                (0.0..=180.0).contains(&self.force_cone_deg),
            ),
        ];
        if let Some((name, _)) = in_range.into_iter().find(|(_, ok)| !ok) {
            return Err(format!("{name} is out of range"));
        }
        if !self.base_position_mm.0.iter().all(|v| v.is_finite()) {
            return Err("base_position_mm must be finite".into());
        }
        if !(self.tip_electrode_stiffness.is_finite() && self.tip_electrode_stiffness > 0.0) {
            return Err("tip_electrode_stiffness must be a positive factor".into());
        }
        if let Some(sheath) = self.sheath
            && !(sheath.free_length_mm.is_finite()
                && (0.0..=200.0).contains(&sheath.free_length_mm)
                && sheath.stiffness_factor.is_finite()
                && sheath.stiffness_factor > 0.0)
        {
            return Err(
                "sheath.free_length_mm must be within 0-200 mm and sheath.stiffness_factor a \
                 positive factor"
                    .into(),
            );
        }
        if let Some(friction) = self.contact_friction
            && !(friction.is_finite() && (0.0..=2.0).contains(&friction))
        {
            return Err(format!(
                "contact_friction {friction} must be between 0 and 2"
            ));
        }
        if let Some(lean) = self.base_lean
            && !(lean.azimuth_deg.is_finite() && (0.0..=90.0).contains(&lean.tilt_deg))
        {
            return Err("base_lean.tilt_deg must be within 0-90° and its azimuth finite".into());
        }
        match &self.plate {
            Some(_) if self.contact_friction.is_some() => Err(
                "contact_friction is for a free tip force: a sensor plate (plate) sets its own \
                 friction"
                    .into(),
            ),
            Some(_) if self.base_lean.is_some() => {
                Err("base_lean cannot be combined with a sensor plate (plate)".into())
            }
            Some(plate) => plate.check(self.length_mm[0]),
            None => Ok(()),
        }
    }

    /// How `scene` lies outside what this sampling draws, one phrase per departure (empty when
    /// it could have been drawn): a network trained on these scenes has not seen such a one.
    /// The tip force's departures first, then the catheter's and its pose's
    /// ([`Self::catheter_departures`]).
    pub fn departures(&self, scene: &SceneParams) -> Vec<String> {
        let mut departures = self.force_departures(scene);
        departures.extend(self.catheter_departures(scene));
        departures
    }

    /// How `scene`'s tip force lies outside what this sampling draws (its magnitude, its
    /// direction).
    fn force_departures(&self, scene: &SceneParams) -> Vec<String> {
        let mut departures = Vec::new();
        let tip_force = Vec3::from(scene.tip_force_n);
        let force = tip_force.norm();
        if outside(force, self.force_magnitude_n) {
            departures.push(format!(
                "|F| {force:.2} N (trained on {})",
                range_text(self.force_magnitude_n, 1.0, "N")
            ));
        }
        if force > 1e-9 {
            let axis = scene.base_frame().column(2);
            let angle = (-tip_force.dot(axis) / force)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            if angle > self.force_cone_deg + 1e-6 {
                departures.push(format!(
                    "the force points {angle:.0}° away from pushing back along the catheter \
                     (trained within {:.0}°)",
                    self.force_cone_deg
                ));
            }
        }
        departures
    }

    /// How `scene`'s catheter (stiffness, length, pre-curvature) and its pose (the base's place,
    /// tilt and roll) lie outside what this sampling draws: what a reader of the images is told
    /// about the scene, never its force.
    pub fn catheter_departures(&self, scene: &SceneParams) -> Vec<String> {
        let mut departures = Vec::new();
        let mut check = |name: &str, value: f64, range: [f64; 2], scale: f64, unit: &str| {
            if outside(value, range) {
                departures.push(format!(
                    "{name} {:.2} {unit} (trained on {})",
                    value * scale,
                    range_text(range, scale, unit)
                ));
            }
        };
        check(
            "stiffness EI",
            scene.bending_stiffness_n_m2,
            self.bending_stiffness_n_m2,
            1e3,
            "mN·m²",
        );
        check(
            "flexible length",
            scene.length_mm,
            self.length_mm,
            1.0,
            "mm",
        );
        check(
            "pre-curvature",
            scene.precurvature_per_mm,
            self.precurvature_per_mm,
            1e3,
            "/m",
        );
        let shift = scene.base_position_mm - self.base_position_mm;
        if shift.max_abs() > self.base_jitter_mm + 1e-6 {
            departures.push(format!(
                "the base moved {:.1} mm (trained within {:.1} mm)",
                shift.max_abs(),
                self.base_jitter_mm
            ));
        }
        // The tilt from the fixture's axis (cranial unless leant).
        let fixture_axis = self
            .base_lean
            .map_or(Vec3::Z, |lean| lean.rotation().column(2));
        let tilt = scene
            .base_frame()
            .column(2)
            .dot(fixture_axis)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        if tilt > self.base_tilt_deg + 1e-6 {
            departures.push(format!(
                "the base tilted {tilt:.0}° (trained within {:.0}°)",
                self.base_tilt_deg
            ));
        }
        let roll = if self.plate.is_some() {
            scene.base_roll_deg + scene.base_azimuth_deg
        } else {
            scene.base_roll_deg
        }
        .rem_euclid(360.0);
        if self.base_roll_deg[1] - self.base_roll_deg[0] < 360.0
            && self.base_lean.is_none()
            && outside(roll, self.base_roll_deg)
        {
            departures.push(format!(
                "the pre-curve's plane turned to {roll:.0}° (trained on {})",
                range_text(self.base_roll_deg, 1.0, "°")
            ));
        }
        departures
    }
}

/// Whether `value` lies outside `range`, allowing for rounding.
fn outside(value: f64, range: [f64; 2]) -> bool {
    const TOLERANCE: f64 = 1e-6;
    value < range[0] - TOLERANCE * range[0].abs().max(1e-3)
        || value > range[1] + TOLERANCE * range[1].abs().max(1e-3)
}

/// `range` scaled by `scale`, as `a-b unit` (or `a unit` when it is one value).
fn range_text(range: [f64; 2], scale: f64, unit: &str) -> String {
    if range[0] == range[1] {
        format!("{:.2} {unit}", range[0] * scale)
    } else {
        format!("{:.2}-{:.2} {unit}", range[0] * scale, range[1] * scale)
    }
}
