//! Static shape of the catheter's flexible distal section: an inextensible, unshearable
//! Kirchhoff rod clamped at its base and loaded by a point force at its tip.
//!
//! Units: millimetres, newtons, N·mm for moments, N/mm² (MPa) for moduli, N·mm² for bending
//! stiffness. Positions and forces are in the world frame.
//!
//! Equations (arc length `s` from the base, `R(s)` the cross-section frame whose third column is
//! the unit tangent):
//!
//! ```text
//! p' = R e3                          (inextensible, unshearable)
//! R' = R [u]×,  u = K⁻¹ Rᵀ m + u*    (K = diag(EI, EI, GJ), u* the intrinsic pre-curvature)
//! n(s) = F + w (L - s)               (internal force: tip force plus the weight beyond s)
//! m' = -p' × n                       (moment balance)
//! ```
//!
//! with `p(0)`, `R(0)` given (clamped base) and `m(L) = R(L) o × F` at the tip (none when the force
//! acts on the centreline's end, `o = 0`; a contact on the tip's rounded surface sits off it).
//! `K` may be stiffer over stretches of the rod ([`StiffSegment`]: a metal tip electrode, the end
//! of a sheath). The unknown base
//! moment `m(0)` is found by shooting: RK4 integration along `s` and Newton's method on
//! `m(L)(m(0)) = 0` with a finite-difference Jacobian and a backtracking line search; large loads
//! are approached by load continuation. A solve that does not reach the tolerance is an error,
//! never a silently wrong shape.

use core::f64::consts::PI;

use serde::{Deserialize, Serialize};

use crate::vec3::{Mat3, Vec3};

mod held;
mod integrate;

pub use held::{HeldJacobian, HeldRod, HeldStart, solve_held};
use integrate::{Problem, solve3};

/// Mechanical and numerical settings of the rod.
///
/// Defaults describe a 7 Fr (2.33 mm) ablation catheter's 50 mm flexible section with a bending
/// stiffness of 0.6 x 10⁻³ N·m² (= 600 N·mm², inside the 0.4-0.9 x 10⁻³ N·m² reported for
/// commercial catheters), straight at rest, without gravity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RodConfig {
    /// Length of the flexible section in mm.
    pub length_mm: f64,
    /// Outer diameter in mm (7 Fr = 2.33 mm).
    pub diameter_mm: f64,
    /// Effective Young's modulus in N/mm² (MPa).
    pub youngs_modulus_mpa: f64,
    /// Effective shear modulus in N/mm² (MPa).
    pub shear_modulus_mpa: f64,
    /// Intrinsic curvature of the unloaded rod about the cross-section's x and y axes, 1/mm.
    pub precurvature_per_mm: [f64; 2],
    /// Arc length from the base where the pre-curved part begins, in mm.
    pub precurve_start_mm: f64,
    /// Mass per length in kg/m (for gravity).
    pub linear_density_kg_per_m: f64,
    /// Gravitational acceleration in m/s² in the world frame; `None` ignores the rod's weight.
    pub gravity_m_per_s2: Option<Vec3>,
    /// RK4 steps along the rod.
    pub steps: usize,
    /// Newton iterations allowed per load step.
    pub max_newton_iterations: usize,
    /// Stretches stiffer than the rest (none: uniform, what every estimate assumes).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stiff_segments: Vec<StiffSegment>,
    /// Where the tip force acts, relative to the centreline's end in the tip's cross-section
    /// frame (x, y across, z along the tangent), mm. Zero (the default, what every estimate
    /// assumes): on the end itself, no tip moment.
    #[serde(default, skip_serializing_if = "Vec3::is_zero")]
    pub tip_load_offset_mm: Vec3,
}

/// A stretch of the rod whose bending and torsional stiffness are `factor` times the rest's: a
/// platinum-iridium tip electrode, or the end of a sheath the catheter runs through.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StiffSegment {
    /// Arc length where it begins, mm from the base.
    pub from_mm: f64,
    /// Arc length where it ends, mm from the base.
    pub to_mm: f64,
    /// Its stiffness over the rest's.
    pub factor: f64,
}

impl Default for RodConfig {
    fn default() -> Self {
        let diameter_mm: f64 = 2.33;
        let second_moment = PI * diameter_mm.powi(4) / 64.0;
        let youngs_modulus_mpa = 600.0 / second_moment;
        Self {
            length_mm: 50.0,
            diameter_mm,
            youngs_modulus_mpa,
            // Poisson's ratio 0.4, typical of the polymer shaft.
            shear_modulus_mpa: youngs_modulus_mpa / (2.0 * 1.4),
            precurvature_per_mm: [0.0, 0.0],
            precurve_start_mm: 0.0,
            // Polymer shaft with braid and lumen: about 1.1 g/cm³ over the full section.
            linear_density_kg_per_m: 1100.0 * PI * (diameter_mm * 1e-3 / 2.0).powi(2),
            gravity_m_per_s2: None,
            steps: 200,
            max_newton_iterations: 40,
            stiff_segments: Vec::new(),
            tip_load_offset_mm: Vec3::ZERO,
        }
    }
}

impl RodConfig {
    /// Second moment of area of the circular section, mm⁴.
    pub fn second_moment_mm4(&self) -> f64 {
        PI * self.diameter_mm.powi(4) / 64.0
    }

    /// Bending stiffness EI in N·mm² (1 N·mm² = 10⁻⁶ N·m²).
    pub fn bending_stiffness_n_mm2(&self) -> f64 {
        self.youngs_modulus_mpa * self.second_moment_mm4()
    }

    /// Torsional stiffness GJ in N·mm² (J = 2I for a circular section).
    pub fn torsional_stiffness_n_mm2(&self) -> f64 {
        self.shear_modulus_mpa * 2.0 * self.second_moment_mm4()
    }

    /// The same rod with Young's modulus (and the shear modulus, keeping their ratio) set so that
    /// the bending stiffness is `ei_n_mm2`.
    pub fn with_bending_stiffness(mut self, ei_n_mm2: f64) -> Self {
        let ratio = self.shear_modulus_mpa / self.youngs_modulus_mpa;
        self.youngs_modulus_mpa = ei_n_mm2 / self.second_moment_mm4();
        self.shear_modulus_mpa = ratio * self.youngs_modulus_mpa;
        self
    }

    fn validate(&self) -> Result<(), RodError> {
        let positive = [
            ("length_mm", self.length_mm),
            ("diameter_mm", self.diameter_mm),
            ("youngs_modulus_mpa", self.youngs_modulus_mpa),
            ("shear_modulus_mpa", self.shear_modulus_mpa),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(RodError::InvalidConfig(format!(
                    "{name} must be a positive number, got {value}"
                )));
            }
        }
        if self.steps < 2 || self.max_newton_iterations == 0 {
            return Err(RodError::InvalidConfig(
                "steps must be at least 2 and max_newton_iterations at least 1".into(),
            ));
        }
        if !self.precurvature_per_mm.iter().all(|k| k.is_finite())
            || !self.linear_density_kg_per_m.is_finite()
            || self
                .gravity_m_per_s2
                .is_some_and(|g| !g.0.iter().all(|v| v.is_finite()))
        {
            return Err(RodError::InvalidConfig(
                "pre-curvature, density and gravity must be finite".into(),
            ));
        }
        for segment in &self.stiff_segments {
            let StiffSegment {
                from_mm,
                to_mm,
                factor,
            } = *segment;
            let within = 0.0 <= from_mm && from_mm < to_mm && to_mm <= self.length_mm;
            if !(within && factor.is_finite() && factor > 0.0) {
                return Err(RodError::InvalidConfig(format!(
                    "stiff segment {from_mm}-{to_mm} mm (x{factor}) must lie within the rod's \
                     {} mm and stiffen it by a positive factor",
                    self.length_mm
                )));
            }
        }
        if !self.tip_load_offset_mm.0.iter().all(|v| v.is_finite()) {
            return Err(RodError::InvalidConfig(
                "tip_load_offset_mm must be finite".into(),
            ));
        }
        Ok(())
    }

    /// How much stiffer than the rest the rod is at arc length `s` (mm): the product of the
    /// factors of the segments holding `s` (1 outside them).
    fn stiffness_factor(&self, s: f64) -> f64 {
        self.stiff_segments
            .iter()
            .filter(|segment| segment.from_mm <= s && s < segment.to_mm)
            .map(|segment| segment.factor)
            .product()
    }

    /// Weight per length in N/mm in the world frame (zero without gravity).
    fn weight_per_mm(&self) -> Vec3 {
        match self.gravity_m_per_s2 {
            // kg/m · m/s² = N/m, and 1 N/m = 10⁻³ N/mm.
            Some(g) => g * (self.linear_density_kg_per_m * 1e-3),
            None => Vec3::ZERO,
        }
    }

    fn intrinsic_curvature(&self, s: f64) -> Vec3 {
        if s >= self.precurve_start_mm {
            Vec3::new(
                self.precurvature_per_mm[0],
                self.precurvature_per_mm[1],
                0.0,
            )
        } else {
            Vec3::ZERO
        }
    }
}

/// The clamped base: position in mm and orientation (columns: the cross-section's x and y axes
/// and the tangent, in the world frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RodBase {
    /// Base position in mm.
    pub position_mm: Vec3,
    /// Base frame; its third column is the direction the rod leaves the base.
    pub orientation: Mat3,
}

impl Default for RodBase {
    fn default() -> Self {
        Self {
            position_mm: Vec3::ZERO,
            orientation: Mat3::IDENTITY,
        }
    }
}

/// The solved centreline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RodShape {
    /// Arc length of each point from the base, mm.
    pub arc_mm: Vec<f64>,
    /// Centreline points, mm, from base to tip.
    pub points_mm: Vec<Vec3>,
    /// Unit tangents at the points.
    pub tangents: Vec<Vec3>,
    /// Reaction moment at the clamp, N·mm.
    pub base_moment_n_mm: Vec3,
    /// Newton iterations used over all load steps.
    pub newton_iterations: usize,
    /// Remaining tip moment |m(L)| in N·mm (the tolerance it met).
    pub residual_n_mm: f64,
}

impl RodShape {
    /// The same shape moved by `offset_mm` (world frame), as a catheter carried by the heart.
    pub fn translated(&self, offset_mm: Vec3) -> Self {
        Self {
            points_mm: self.points_mm.iter().map(|&p| p + offset_mm).collect(),
            ..self.clone()
        }
    }

    /// The part from arc length `arc_mm` to the tip, its arc lengths counted from there (the
    /// first point kept is the first at or beyond `arc_mm`). Its base moment stays the one at
    /// the whole rod's base.
    pub fn distal_from(&self, arc_mm: f64) -> Self {
        let first = self
            .arc_mm
            .iter()
            .position(|&s| s >= arc_mm - 1e-9)
            .unwrap_or(self.arc_mm.len().saturating_sub(2))
            .min(self.arc_mm.len().saturating_sub(2));
        let start = self.arc_mm[first];
        Self {
            arc_mm: self.arc_mm[first..].iter().map(|s| s - start).collect(),
            points_mm: self.points_mm[first..].to_vec(),
            tangents: self.tangents[first..].to_vec(),
            ..self.clone()
        }
    }

    /// The tip position in mm.
    pub fn tip_mm(&self) -> Vec3 {
        *self
            .points_mm
            .last()
            .expect("a shape has at least two points")
    }
}

/// Why the rod could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RodError {
    /// A setting or the load is not usable.
    #[error("invalid rod settings: {0}")]
    InvalidConfig(String),
    /// Newton's method did not reach the tolerance, even with load continuation.
    #[error(
        "rod solver did not converge: tip moment {residual_n_mm:.3e} N·mm after {iterations} Newton iterations (tolerance {tolerance_n_mm:.1e} N·mm)"
    )]
    NotConverged {
        /// Newton iterations spent.
        iterations: usize,
        /// Smallest tip moment reached, N·mm.
        residual_n_mm: f64,
        /// The tolerance, N·mm.
        tolerance_n_mm: f64,
    },
}

/// How far a chord step (Newton's step with a Jacobian reused from a nearby solve) must bring the
/// residual down, as a share of where it was, to be kept: else a fresh Jacobian is computed.
/// [`solve_near`]'s and [`solve_held`]'s.
const CHORD_KEPT_BELOW: f64 = 0.5;

/// Where Newton's method on the base moment ended for one solved rod: the start for rods whose
/// settings, base and load differ little from its own ([`solve_near`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonStart {
    /// The base moment, N·mm (world frame).
    pub base_moment_n_mm: Vec3,
    /// The last Jacobian of the tip's moment with respect to the base moment (dimensionless),
    /// when one was computed: reused for a nearby rod while it converges (the chord method),
    /// instead of three integrations an iteration.
    jacobian: Option<[[f64; 3]; 3]>,
}

/// Where Newton's method ended for one load: there, the shape there, the iterations used and the
/// tip moment left, N·mm.
type Solved = (NewtonStart, RodShape, usize, f64);

/// Newton's method on the base moment for one load, from `start` (and its Jacobian, while that
/// halves the residual at each full step). `Err` carries the iterations and the best residual
/// when it fails.
fn newton(
    problem: &Problem<'_>,
    start: NewtonStart,
    tolerance: f64,
    scale: f64,
) -> Result<Solved, (usize, f64)> {
    let NewtonStart {
        base_moment_n_mm: mut m0,
        mut jacobian,
    } = start;
    // The shots at the iterates record their shape, so that the last one is the solution's.
    let shot = |m0: Vec3| {
        let (residual, shape) = problem.shoot(m0, true);
        (residual, shape.expect("recorded"))
    };
    let (mut residual, mut shape) = shot(m0);
    let mut norm = residual.norm();
    // Whether `jacobian` was computed at one of this load's iterates.
    let mut fresh = false;
    for iteration in 0..problem.config.max_newton_iterations {
        if !norm.is_finite() {
            return Err((iteration, norm));
        }
        let ended = |m0, jacobian| NewtonStart {
            base_moment_n_mm: m0,
            jacobian,
        };
        if norm <= tolerance {
            return Ok((ended(m0, jacobian), shape, iteration, norm));
        }
        if let Some(known) = jacobian.filter(|_| !fresh) {
            // The chord step: kept at full length only where it halves the residual.
            if let Some(step) = solve3(known, -residual) {
                let candidate = m0 + step;
                let (r, candidate_shape) = shot(candidate);
                let n = r.norm();
                if n.is_finite() && n <= CHORD_KEPT_BELOW * norm {
                    m0 = candidate;
                    residual = r;
                    shape = candidate_shape;
                    norm = n;
                    continue;
                }
            }
        }
        let h = 1e-7 * m0.max_abs().max(scale);
        let mut fd = [[0.0; 3]; 3];
        for j in 0..3 {
            let mut probe = m0;
            probe.0[j] += h;
            let column = (problem.shoot(probe, false).0 - residual) / h;
            for (i, row) in fd.iter_mut().enumerate() {
                row[j] = column[i];
            }
        }
        jacobian = Some(fd);
        fresh = true;
        let Some(step) = solve3(fd, -residual) else {
            return Err((iteration, norm));
        };
        let mut alpha = 1.0;
        loop {
            let candidate = m0 + step * alpha;
            let (r, candidate_shape) = shot(candidate);
            let n = r.norm();
            if n.is_finite() && n < (1.0 - 1e-4 * alpha) * norm {
                m0 = candidate;
                residual = r;
                shape = candidate_shape;
                norm = n;
                break;
            }
            alpha /= 2.0;
            if alpha < 1e-6 {
                return Err((iteration + 1, norm));
            }
        }
    }
    if norm <= tolerance {
        let end = NewtonStart {
            base_moment_n_mm: m0,
            jacobian,
        };
        Ok((end, shape, problem.config.max_newton_iterations, norm))
    } else {
        Err((problem.config.max_newton_iterations, norm))
    }
}

/// Solves the static shape of the rod clamped at `base` under `tip_force_n` (N, world frame).
pub fn solve(config: &RodConfig, base: &RodBase, tip_force_n: Vec3) -> Result<RodShape, RodError> {
    Loads::new(config, base, tip_force_n)?
        .solve()
        .map(|(shape, _)| shape)
}

/// Solves as [`solve`], starting Newton's method at full load from `start`: where it ended for a
/// solved rod whose settings, base and load differ little from these, as a rod fit's
/// finite-difference probe differs from the rod it probes. From there Newton's method needs an
/// iteration or two and no new Jacobian, where [`solve`] needs several iterations from the rigid
/// rod's moment. The tolerance is [`solve`]'s; without `start`, or where it does not converge
/// from there, [`solve`]'s own path is taken. Also returns where this rod's solve ended.
pub fn solve_near(
    config: &RodConfig,
    base: &RodBase,
    tip_force_n: Vec3,
    start: Option<&NewtonStart>,
) -> Result<(RodShape, NewtonStart), RodError> {
    let loads = Loads::new(config, base, tip_force_n)?;
    let near = start
        .and_then(|start| newton(&loads.at(1.0), *start, loads.tolerance * 1e-3, loads.scale).ok());
    match near {
        Some((end, shape, iterations, residual)) => {
            Ok((Loads::finished(shape, iterations, residual), end))
        }
        None => loads.solve(),
    }
}

/// One rod under one load, checked, with the scale of its moments.
struct Loads<'a> {
    config: &'a RodConfig,
    base: &'a RodBase,
    tip_force: Vec3,
    weight: Vec3,
    stiffness: Vec3,
    /// The moments' scale, N·mm: the largest of the tip force's and the weight's moments over the
    /// rod and its stiffness over its length.
    scale: f64,
    /// Newton's tolerance on the tip's moment, N·mm.
    tolerance: f64,
}

impl<'a> Loads<'a> {
    fn new(config: &'a RodConfig, base: &'a RodBase, tip_force_n: Vec3) -> Result<Self, RodError> {
        config.validate()?;
        if !tip_force_n.0.iter().all(|f| f.is_finite()) {
            return Err(RodError::InvalidConfig(format!(
                "tip force must be finite, got {:?} N",
                tip_force_n.0
            )));
        }
        let ei = config.bending_stiffness_n_mm2();
        let weight = config.weight_per_mm();
        let length = config.length_mm;
        let scale = (tip_force_n.norm() * length)
            .max(ei / length)
            .max(weight.norm() * length * length);
        Ok(Self {
            config,
            base,
            tip_force: tip_force_n,
            weight,
            stiffness: Vec3::new(ei, ei, config.torsional_stiffness_n_mm2()),
            scale,
            tolerance: 1e-10 * scale,
        })
    }

    /// The problem with `fraction` of the loads.
    fn at(&self, fraction: f64) -> Problem<'a> {
        Problem {
            config: self.config,
            base: self.base,
            tip_force: self.tip_force * fraction,
            weight: self.weight * fraction,
            stiffness: self.stiffness,
        }
    }

    /// The solution's `shape`, reached after `iterations` Newton iterations with `residual`
    /// left (N·mm).
    fn finished(mut shape: RodShape, iterations: usize, residual: f64) -> RodShape {
        shape.newton_iterations = iterations;
        shape.residual_n_mm = residual;
        shape
    }

    /// Newton's method from the rigid rod's moment, at full load, then with load continuation in
    /// ever finer steps.
    fn solve(&self) -> Result<(RodShape, NewtonStart), RodError> {
        let length = self.config.length_mm;
        // The unloaded shape gives the first guess: the moment of the loads about the base for a
        // rigid rod of that shape, m(0) = ∫ p' × n ds.
        let rest = self.at(0.0).shoot(Vec3::ZERO, true).1.expect("recorded");
        let guess = |fraction: f64| {
            let problem = self.at(fraction);
            let h = length / self.config.steps as f64;
            rest.tangents
                .windows(2)
                .enumerate()
                .fold(Vec3::ZERO, |acc, (i, t)| {
                    let s = (i as f64 + 0.5) * h;
                    let n = problem.tip_force + problem.weight * (length - s);
                    acc + ((t[0] + t[1]) * 0.5).cross(n) * h
                })
        };

        let mut total_iterations = 0;
        let mut best_residual = f64::INFINITY;
        // Full load first; then load continuation in ever finer steps.
        for load_steps in [1usize, 4, 16, 64] {
            let mut m0 = guess(1.0 / load_steps as f64);
            let mut previous = Vec3::ZERO;
            let mut solved = None;
            for step in 1..=load_steps {
                let fraction = step as f64 / load_steps as f64;
                let start = NewtonStart {
                    base_moment_n_mm: m0,
                    jacobian: None,
                };
                match newton(&self.at(fraction), start, self.tolerance, self.scale) {
                    Ok((end, shape, iterations, residual)) => {
                        let m = end.base_moment_n_mm;
                        total_iterations += iterations;
                        // Extrapolate linearly to the next load step.
                        let next = m + (m - previous);
                        previous = m;
                        m0 = next;
                        if step == load_steps {
                            solved = Some((end, shape, residual));
                        }
                    }
                    Err((iterations, residual)) => {
                        total_iterations += iterations;
                        best_residual = best_residual.min(residual);
                        break;
                    }
                }
            }
            if let Some((end, shape, residual)) = solved {
                return Ok((Self::finished(shape, total_iterations, residual), end));
            }
        }
        Err(RodError::NotConverged {
            iterations: total_iterations,
            residual_n_mm: best_residual,
            tolerance_n_mm: self.tolerance,
        })
    }
}

/// The frame of the rod's tip under no tip load (columns: the cross-section's x and y axes and
/// the tangent, world frame).
pub fn rest_tip_frame(config: &RodConfig, base: &RodBase) -> Result<Mat3, RodError> {
    let loads = Loads::new(config, base, Vec3::ZERO)?;
    let (rest, _) = loads.solve()?;
    Ok(loads
        .at(1.0)
        .integrate(rest.base_moment_n_mm, false)
        .tip_frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 100 mm rod with EI = 1000 N·mm², clamped at the origin pointing along +z.
    fn beam() -> RodConfig {
        RodConfig {
            length_mm: 100.0,
            ..RodConfig::default()
        }
        .with_bending_stiffness(1000.0)
    }

    fn relative_error(actual: f64, expected: f64) -> f64 {
        ((actual - expected) / expected).abs()
    }

    #[test]
    fn default_stiffness_is_in_the_clinical_range() {
        let ei = RodConfig::default().bending_stiffness_n_mm2();
        // 0.4-0.9 x 10⁻³ N·m² = 400-900 N·mm².
        assert!((400.0..=900.0).contains(&ei), "{ei}");
        assert!((ei - 600.0).abs() < 1e-9);
    }

    #[test]
    fn small_loads_match_linear_beam_theory() {
        let config = beam();
        let ei = config.bending_stiffness_n_mm2();
        let l = config.length_mm;
        // FL²/EI = 0.01: the linear regime.
        let f = 0.01 * ei / (l * l);
        let shape = solve(&config, &RodBase::default(), Vec3::new(f, 0.0, 0.0)).unwrap();
        let expected = f * l.powi(3) / (3.0 * ei);
        let tip = shape.tip_mm();
        assert!(
            relative_error(tip.x(), expected) < 0.01,
            "tip deflection {} mm, FL³/3EI = {expected} mm",
            tip.x()
        );
        assert!(tip.y().abs() < 1e-9);
    }

    #[test]
    fn large_deflections_match_the_elastica() {
        // Bisshopp & Drucker (1945): a cantilever under a dead end load P perpendicular to its
        // undeformed axis. PL²/EI = 1: tip deflection 0.302 L, shortening 0.0566 L;
        // PL²/EI = 2: 0.494 L and 0.161 L.
        let config = beam();
        let ei = config.bending_stiffness_n_mm2();
        let l = config.length_mm;
        for (alpha, deflection, shortening) in [(1.0, 0.302, 0.0566), (2.0, 0.494, 0.161)] {
            let f = alpha * ei / (l * l);
            let tip = solve(&config, &RodBase::default(), Vec3::new(f, 0.0, 0.0))
                .unwrap()
                .tip_mm();
            let d = tip.x() / l;
            let s = (l - tip.z()) / l;
            assert!(
                relative_error(d, deflection) < 0.01,
                "PL²/EI = {alpha}: deflection {d} L, expected {deflection} L"
            );
            assert!(
                relative_error(s, shortening) < 0.01,
                "PL²/EI = {alpha}: shortening {s} L, expected {shortening} L"
            );
        }
    }

    /// A rod fit's probe: started from where a nearby rod's solve ended, the solve reaches the
    /// same shape as from scratch, in fewer iterations, and falls back to the full path from a
    /// start far away.
    #[test]
    fn a_solve_near_a_solved_rod_gives_the_same_shape() {
        let config = RodConfig {
            precurvature_per_mm: [1.0 / 60.0, 0.0],
            ..beam()
        };
        let base = RodBase::default();
        let force = Vec3::new(0.15, -0.05, -0.1);
        let (solved, end) = solve_near(&config, &base, force, None).unwrap();
        assert_eq!(solved, solve(&config, &base, force).unwrap());
        let probe = force + Vec3::new(1e-6, 0.0, 0.0);
        let cold = solve(&config, &base, probe).unwrap();
        for start in [
            end,
            NewtonStart {
                jacobian: None,
                ..end
            },
        ] {
            let (near, _) = solve_near(&config, &base, probe, Some(&start)).unwrap();
            for (a, b) in near.points_mm.iter().zip(&cold.points_mm) {
                assert!((*a - *b).max_abs() < 1e-9, "{a:?} vs {b:?}");
            }
            assert!(near.newton_iterations < cold.newton_iterations);
        }
        // A start from another load entirely still converges, to the same shape.
        let far = NewtonStart {
            base_moment_n_mm: Vec3::new(50.0, -80.0, 3.0),
            ..end
        };
        let (from_far, _) = solve_near(&config, &base, probe, Some(&far)).unwrap();
        for (a, b) in from_far.points_mm.iter().zip(&cold.points_mm) {
            assert!((*a - *b).max_abs() < 1e-9, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn zero_force_gives_the_precurved_rest_shape() {
        let kappa = 1.0 / 40.0;
        let config = RodConfig {
            precurvature_per_mm: [kappa, 0.0],
            ..RodConfig::default()
        };
        let shape = solve(&config, &RodBase::default(), Vec3::ZERO).unwrap();
        // A circular arc: bending about the section's x axis turns the tangent towards -y.
        for (s, p) in shape.arc_mm.iter().zip(&shape.points_mm) {
            let expected = Vec3::new(
                0.0,
                -(1.0 - (kappa * s).cos()) / kappa,
                (kappa * s).sin() / kappa,
            );
            assert!(
                (*p - expected).max_abs() < 1e-6,
                "at s = {s}: {p:?} vs {expected:?}"
            );
        }
        assert!(shape.base_moment_n_mm.norm() < 1e-9);
    }

    #[test]
    fn a_rotated_base_rotates_the_shape() {
        let config = beam();
        let force = Vec3::new(0.05, 0.0, 0.0);
        let straight = solve(&config, &RodBase::default(), force).unwrap();
        let turn = Mat3::rotation(Vec3::Z, 0.9);
        let base = RodBase {
            position_mm: Vec3::new(1.0, 2.0, 3.0),
            orientation: turn,
        };
        let turned = solve(&config, &base, turn * force).unwrap();
        let expected = turn * straight.tip_mm() + base.position_mm;
        assert!((turned.tip_mm() - expected).max_abs() < 1e-6);
    }

    #[test]
    fn gravity_bends_a_horizontal_rod_downwards() {
        let config = RodConfig {
            gravity_m_per_s2: Some(Vec3::new(0.0, 0.0, -9.81)),
            ..RodConfig::default()
        };
        // Base pointing along +x: the rod's weight acts across it.
        let base = RodBase {
            position_mm: Vec3::ZERO,
            orientation: Mat3::rotation(Vec3::Y, core::f64::consts::FRAC_PI_2),
        };
        let shape = solve(&config, &base, Vec3::ZERO).unwrap();
        let w = config.linear_density_kg_per_m * 9.81 * 1e-3;
        let l = config.length_mm;
        // Uniform load: δ = wL⁴ / 8EI.
        let expected = w * l.powi(4) / (8.0 * config.bending_stiffness_n_mm2());
        assert!(relative_error(-shape.tip_mm().z(), expected) < 0.01);
    }

    #[test]
    fn failing_to_converge_is_an_error_not_a_shape() {
        let config = RodConfig {
            max_newton_iterations: 1,
            ..beam()
        };
        let f = 2.0 * config.bending_stiffness_n_mm2() / config.length_mm.powi(2);
        let err = solve(&config, &RodBase::default(), Vec3::new(f, 0.0, 0.0)).unwrap_err();
        assert!(matches!(err, RodError::NotConverged { .. }), "{err}");
        assert!(err.to_string().contains("did not converge"));
    }

    #[test]
    fn bad_inputs_are_rejected() {
        let config = RodConfig {
            length_mm: -1.0,
            ..RodConfig::default()
        };
        assert!(matches!(
            solve(&config, &RodBase::default(), Vec3::ZERO),
            Err(RodError::InvalidConfig(_))
        ));
        assert!(matches!(
            solve(
                &RodConfig::default(),
                &RodBase::default(),
                Vec3::new(f64::NAN, 0.0, 0.0)
            ),
            Err(RodError::InvalidConfig(_))
        ));
    }

    #[test]
    fn stiff_segments_and_an_offset_tip_load_are_what_they_say() {
        let config = beam();
        let ei = config.bending_stiffness_n_mm2();
        let l = config.length_mm;
        let f = 0.01 * ei / (l * l);
        let base = RodBase::default();
        // One segment over the whole rod is a rod that much stiffer.
        let whole = RodConfig {
            stiff_segments: vec![StiffSegment {
                from_mm: 0.0,
                to_mm: l,
                factor: 3.0,
            }],
            ..config.clone()
        };
        let stiffer = config.clone().with_bending_stiffness(3.0 * ei);
        let load = Vec3::new(f, 0.0, 0.0);
        let (a, b) = (
            solve(&whole, &base, load).unwrap().tip_mm(),
            solve(&stiffer, &base, load).unwrap().tip_mm(),
        );
        assert!((a - b).norm() < 1e-9, "{a:?} {b:?}");
        // A rigid last tenth: the flexible nine tenths' deflection at their end (a = 0.9 L,
        // loaded by F and the moment F (L - a)), carried on straight at their end's slope.
        let rigid_tip = RodConfig {
            stiff_segments: vec![StiffSegment {
                from_mm: 0.9 * l,
                to_mm: l,
                factor: 1e6,
            }],
            ..config.clone()
        };
        let a = 0.9 * l;
        let deflection = f * a.powi(3) / (3.0 * ei) + f * (l - a) * a * a / (2.0 * ei);
        let slope = f * a * a / (2.0 * ei) + f * (l - a) * a / ei;
        let expected = deflection + slope * (l - a);
        let tip = solve(&rigid_tip, &base, load).unwrap().tip_mm();
        assert!(
            relative_error(tip.x(), expected) < 0.02,
            "rigid tip: {} mm, beam theory {expected} mm",
            tip.x()
        );
        // A push along the rod applied r off its axis bends it as the moment r F does: M L²/2EI.
        let r = 1.0;
        let eccentric = RodConfig {
            tip_load_offset_mm: Vec3::new(r, 0.0, 0.0),
            ..config.clone()
        };
        let tip = solve(&eccentric, &base, Vec3::new(0.0, 0.0, -f))
            .unwrap()
            .tip_mm();
        let expected = r * f * l * l / (2.0 * ei);
        assert!(
            relative_error(tip.x().abs(), expected) < 0.02 && tip.y().abs() < 1e-9,
            "eccentric push: {tip:?}, M L²/2EI = {expected} mm"
        );
        let outside = RodConfig {
            stiff_segments: vec![StiffSegment {
                from_mm: 0.5 * l,
                to_mm: 2.0 * l,
                factor: 2.0,
            }],
            ..config
        };
        assert!(matches!(
            solve(&outside, &base, load),
            Err(RodError::InvalidConfig(message)) if message.contains("stiff segment")
        ));
    }
}
