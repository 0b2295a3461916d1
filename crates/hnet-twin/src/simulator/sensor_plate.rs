//! The paper's bench contact: the catheter's tip pressed against a flat force-sensor plate that
//! two motorised linear actuators move (Fekri et al., IEEE RA-L 2024, "two motorised linear
//! actuators press the tip against a force sensor").
//!
//! The contact is a displacement, not a force: the press actuator moves the plate along its
//! normal towards the catheter, then the slide actuator drags it in its own plane. The rod is
//! solved with its tip held where the plate put it, and the tip force is read from that solution:
//!
//! - **stick**: the tip stays at the point of the plate it first touched, carried by both moves;
//!   the force is the one whose solved rod ends there (3 unknowns, 3 equations);
//! - **slip**: when that force leaves Coulomb's friction cone (`|F_t| > μ F_n`), the tip slides
//!   on the plate until the tangential force sits on the cone, pointing from the tip towards the
//!   point it would have stuck to (the plate drags it). Unknowns: the normal force and the tip's
//!   two coordinates on the plate.
//!
//! Both are solved as the rod's boundary-value problem with the tip held
//! ([`crate::simulator::rod::solve_held`]: the base moment and the three contact unknowns together). A final state is taken as path independent (a monotonic press,
//! then a monotonic slide), and the contact is a point at the end of the centreline (the tip's
//! rounding and the plate's compliance are left out). A solve that does not converge, a shaft that
//! would cross the plate or a contact that would pull are errors, never a wrong shape.
//!
//! Units: millimetres, newtons. Forces are those the plate applies to the tip, world frame (the
//! twin's label convention; the sensor reads the opposite).

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

use crate::simulator::rod::{
    self, HeldJacobian, HeldStart, RodBase, RodConfig, RodError, RodShape,
};
use crate::vec3::Vec3;

/// The sensor plate and its two actuators: the settings of a set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorPlate {
    /// Gap between the unloaded catheter's tip (on the fixture's nominal base) and the plate at
    /// the actuators' zero, along the plate's normal, mm. The plate is square to the fixture's
    /// axis, beyond the tip ([`Self::pose`]).
    pub standoff_mm: f64,
    /// Range of the angle between the plate's normal and the fixture's axis, degrees: the
    /// sensor is mounted at an angle to the catheter.
    pub tilt_deg: [f64; 2],
    /// Range of the direction of that tilt about the fixture's axis, degrees: the stage is
    /// turned about the catheter between recordings.
    pub tilt_azimuth_deg: [f64; 2],
    /// Travel of the press actuator, which moves the plate along its normal towards the
    /// catheter, mm.
    pub press_mm: [f64; 2],
    /// Travel of the slide actuator, which then moves the plate in its own plane, mm.
    pub slide_mm: [f64; 2],
    /// Direction of the slide in the plate's plane, degrees about its normal from the plate's
    /// first axis ([`PlatePose::axes`]): the stage is turned between recordings.
    pub slide_azimuth_deg: [f64; 2],
    /// Coulomb friction coefficient between the tip and the plate.
    pub friction: f64,
    /// The force sensor's range, N: the bench records no contact above it.
    pub max_force_n: f64,
}

impl SensorPlate {
    /// The bench's plate: 0.5 mm from the unloaded tip, tilted up to 30° from square to the
    /// fixture in any direction, pressed 0.8-4.0 mm (0.3-3.5 mm into the catheter), slid ±3 mm
    /// in any direction of its plane, friction 0.3 (a polymer tip on an anodised plate), a
    /// 0.6 N sensor (docs/twin.md, "The paper's bench").
    pub fn bench() -> Self {
        Self {
            standoff_mm: 0.5,
            tilt_deg: [0.0, 30.0],
            tilt_azimuth_deg: [0.0, 360.0],
            press_mm: [0.8, 4.0],
            slide_mm: [-3.0, 3.0],
            slide_azimuth_deg: [0.0, 180.0],
            friction: 0.3,
            max_force_n: 0.6,
        }
    }

    /// Why these settings cannot be used with a catheter whose flexible section is
    /// `length_mm` long, naming the setting: an unloaded tip already through the plate, a plate
    /// the actuators never bring to the tip, more press than the section can take without
    /// folding (the tip would go through the plate), reversed or infinite ranges, a negative
    /// friction.
    pub fn check(&self, length_mm: f64) -> Result<(), String> {
        for (name, [lo, hi]) in [
            ("plate.tilt_deg", self.tilt_deg),
            ("plate.tilt_azimuth_deg", self.tilt_azimuth_deg),
            ("plate.press_mm", self.press_mm),
            ("plate.slide_mm", self.slide_mm),
            ("plate.slide_azimuth_deg", self.slide_azimuth_deg),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(format!(
                    "{name} must be a range [low, high] of finite numbers, low ≤ high"
                ));
            }
        }
        if !(self.standoff_mm.is_finite() && self.standoff_mm >= 0.0) {
            return Err(format!(
                "plate.standoff_mm {} puts the unloaded tip through the plate (it must be ≥ 0)",
                self.standoff_mm
            ));
        }
        if self.tilt_deg[0] < 0.0 || self.tilt_deg[1] > 60.0 {
            return Err(
                "plate.tilt_deg must stay within 0-60°: a steeper plate meets the shaft, not the tip"
                    .into(),
            );
        }
        if self.press_mm[0] < 0.0 {
            return Err("plate.press_mm must not pull the plate away (low ≥ 0)".into());
        }
        if self.press_mm[1] <= self.standoff_mm {
            return Err(format!(
                "plate.press_mm reaches {} mm, never the tip {} mm away (plate.standoff_mm): the \
                 catheter cannot reach the plate",
                self.press_mm[1], self.standoff_mm
            ));
        }
        let deepest = self.press_mm[1] - self.standoff_mm;
        if deepest > 0.25 * length_mm {
            return Err(format!(
                "plate.press_mm presses {deepest} mm into a {length_mm} mm section: more than a \
                 quarter of it, the tip would go through the plate"
            ));
        }
        if !(self.max_force_n.is_finite() && self.max_force_n > 0.0) {
            return Err("plate.max_force_n must be a positive number of newtons".into());
        }
        if !(self.friction.is_finite() && (0.0..=2.0).contains(&self.friction)) {
            return Err(format!(
                "plate.friction {} must be between 0 and 2",
                self.friction
            ));
        }
        Ok(())
    }

    /// Draws one pair's actuator positions, uniform over each travel.
    pub fn draw(&self, rng: &mut impl Rng) -> PlateContact {
        let mut uniform = |[lo, hi]: [f64; 2]| lo + (hi - lo) * rng.random::<f64>();
        PlateContact {
            tilt_deg: uniform(self.tilt_deg),
            tilt_azimuth_deg: uniform(self.tilt_azimuth_deg),
            press_mm: uniform(self.press_mm),
            slide_mm: uniform(self.slide_mm),
            slide_azimuth_deg: uniform(self.slide_azimuth_deg),
            state: ContactState::Free,
        }
    }

    /// Where the plate is at the actuators' zero for a pair's `contact`: its normal the
    /// fixture's axis (of the nominal base `nominal_base`) reversed and tilted by the contact's
    /// tilt, `standoff_mm` beyond the unloaded tip `nominal_rest`.
    pub fn pose(
        &self,
        nominal_base: &RodBase,
        nominal_rest: &RodShape,
        contact: &PlateContact,
    ) -> PlatePose {
        let axis = nominal_base.orientation.column(2).normalized();
        let across = nominal_base.orientation.column(0).normalized();
        let (tilt, azimuth) = (
            contact.tilt_deg.to_radians(),
            contact.tilt_azimuth_deg.to_radians(),
        );
        let sideways = across * azimuth.cos() + axis.cross(across) * azimuth.sin();
        let normal = -(axis * tilt.cos() + sideways * tilt.sin()).normalized();
        // The plate's first axis: world y (anterior, towards view A's camera) made
        // perpendicular to the normal.
        let reference = if normal.y().abs() < 0.9 {
            Vec3::Y
        } else {
            Vec3::X
        };
        let first = (reference - normal * reference.dot(normal)).normalized();
        PlatePose {
            point_mm: nominal_rest.tip_mm() - normal * self.standoff_mm,
            normal,
            axes: [first, normal.cross(first)],
        }
    }
}

/// The plate's face at the actuators' zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlatePose {
    /// A point of the face, mm.
    pub point_mm: Vec3,
    /// Unit normal, pointing towards the catheter.
    pub normal: Vec3,
    /// Two unit axes in the face, perpendicular to each other and to the normal.
    pub axes: [Vec3; 2],
}

/// How the tip met the plate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ContactState {
    /// The plate never reached the tip: no force.
    #[default]
    Free,
    /// The tip stayed where it touched the plate.
    Stick,
    /// The tip slid on the plate; the tangential force is on the friction cone.
    Slip,
}

impl ContactState {
    /// `free`, `stick` or `slip`.
    pub fn name(self) -> &'static str {
        match self {
            ContactState::Free => "free",
            ContactState::Stick => "stick",
            ContactState::Slip => "slip",
        }
    }
}

/// One pair's actuator positions and how the tip met the plate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlateContact {
    /// Angle between the plate's normal and the fixture's axis, degrees.
    pub tilt_deg: f64,
    /// Direction of that tilt about the fixture's axis, degrees from the base's first section
    /// axis.
    pub tilt_azimuth_deg: f64,
    /// Press actuator position, mm from its zero towards the catheter.
    pub press_mm: f64,
    /// Slide actuator position, mm.
    pub slide_mm: f64,
    /// Slide direction, degrees about the plate's normal.
    pub slide_azimuth_deg: f64,
    /// The solved contact (`free` until solved).
    pub state: ContactState,
}

/// Why a contact could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ContactError {
    /// The rod itself could not be solved under a trial force.
    #[error(transparent)]
    Rod(#[from] RodError),
    /// Newton's method on the sliding contact did not reach a consistent solution.
    #[error("the {state} contact did not converge after {iterations} iterations")]
    NotConverged {
        /// `slip`.
        state: &'static str,
        /// Iterations spent.
        iterations: usize,
    },
    /// The solved shaft crosses the plate before the tip.
    #[error("the shaft crosses the plate {depth_mm:.2} mm before the tip")]
    ShaftThroughPlate {
        /// How far behind the plate's face the deepest point is, mm.
        depth_mm: f64,
    },
    /// The contact is beyond the force sensor's range.
    #[error("{force_n:.2} N is beyond the force sensor's {max_force_n} N range")]
    BeyondSensorRange {
        /// The force, N.
        force_n: f64,
        /// The sensor's range, N.
        max_force_n: f64,
    },
    /// Holding the tip would need the plate to pull it.
    #[error("the plate would have to pull the tip (normal force {normal_n:.3} N)")]
    Pulling {
        /// The normal force, N (negative).
        normal_n: f64,
    },
}

/// The solved contact: the catheter's shape, the tip force (N, on the tip, world frame) and
/// whether the tip stuck or slid.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactSolution {
    /// The centreline.
    pub shape: RodShape,
    /// Force the plate applies to the tip, N, world frame.
    pub tip_force_n: Vec3,
    /// Stick, slip, or free when the plate never reached the tip.
    pub state: ContactState,
}

/// Tip positions are held to this, mm.
const TOLERANCE_MM: f64 = 1e-6;
/// Steps of each actuator's move along the loading path (press, then slide).
const PATH_STEPS: usize = 8;

/// Solves the rod `config` clamped at `base` with its tip held by `plate` at `pose` moved to
/// `contact`'s actuator positions.
///
/// The loading path is followed quasi-statically: the press in `PATH_STEPS` steps from the
/// moment the plate touches the tip, then the slide in as many. At each step the tip first
/// tries to stay on the point of the plate it rests on; if that takes a tangential force
/// outside the friction cone it slides, and the point it comes to rest on is where the next step
/// starts.
pub fn solve(
    config: &RodConfig,
    base: &RodBase,
    plate: &SensorPlate,
    pose: &PlatePose,
    contact: &PlateContact,
) -> Result<ContactSolution, ContactError> {
    let friction = plate.friction;
    let rest = rod::solve(config, base, Vec3::ZERO)?;
    let rest_tip = rest.tip_mm();
    let n = pose.normal;
    // How far the plate travels before it touches this catheter's unloaded tip (the fixture's
    // play moves it a little from the nominal one).
    let gap = (rest_tip - pose.point_mm).dot(n);
    let depth = contact.press_mm - gap;
    if depth <= 0.0 {
        return Ok(ContactSolution {
            shape: rest,
            tip_force_n: Vec3::ZERO,
            state: ContactState::Free,
        });
    }
    let [e1, e2] = pose.axes;
    let azimuth = contact.slide_azimuth_deg.to_radians();
    let slide = (e1 * azimuth.cos() + e2 * azimuth.sin()) * contact.slide_mm;
    let moves = std::iter::repeat_n(n * (depth / PATH_STEPS as f64), PATH_STEPS).chain(
        std::iter::repeat_n(slide / PATH_STEPS as f64, PATH_STEPS)
            .filter(|_| contact.slide_mm != 0.0),
    );
    // The point of the plate the tip rests on (world, mm), the force holding it there, and the
    // moves still to make (a stack: a step that fails is made in two halves).
    let mut at = Rest {
        anchor: rest_tip,
        force: Vec3::ZERO,
        base_moment: Some(rest.base_moment_n_mm),
        jacobians: Jacobians::default(),
        state: ContactState::Stick,
    };
    let mut pending: Vec<Vec3> = moves.collect();
    pending.reverse();
    while let Some(step) = pending.pop() {
        match contact_step(config, base, &at, step, pose, friction) {
            Ok(next) => at = next,
            Err(_) if step.norm() > MIN_STEP_MM => pending.extend([step * 0.5, step * 0.5]),
            Err(e) => return Err(e),
        }
    }
    let Rest { force, state, .. } = at;
    let normal_n = force.dot(n);
    if normal_n <= 0.0 {
        return Err(ContactError::Pulling { normal_n });
    }
    if force.norm() > plate.max_force_n {
        return Err(ContactError::BeyondSensorRange {
            force_n: force.norm(),
            max_force_n: plate.max_force_n,
        });
    }
    let shape = rod::solve(config, base, force)?;
    // The plate's face after the press: every point but the tip must stay on the catheter's
    // side of it (the tip lies on it).
    let face = pose.point_mm + n * contact.press_mm;
    let deepest = shape.points_mm[..shape.points_mm.len() - 1]
        .iter()
        .map(|&p| (p - face).dot(n))
        .fold(f64::INFINITY, f64::min);
    if deepest < -TOLERANCE_MM * 10.0 {
        return Err(ContactError::ShaftThroughPlate { depth_mm: -deepest });
    }
    Ok(ContactSolution {
        shape,
        tip_force_n: force,
        state,
    })
}

/// Where the tip rests on the plate along the loading path.
struct Rest {
    /// The point of the plate it rests on, world, mm.
    anchor: Vec3,
    /// The force the plate applies to it there, N.
    force: Vec3,
    /// The rod's base moment there, N·mm (a start for the next step).
    base_moment: Option<Vec3>,
    /// The last Jacobians of the held solves that sticking and sliding take (a start for the
    /// next step's of the same kind).
    jacobians: Jacobians,
    /// Whether it got there sticking or sliding.
    state: ContactState,
}

/// The last Jacobians of the two holds along the path ([`HeldStart::jacobian`]): their
/// parameters mean different things (the force when sticking; the normal force, the slide's
/// direction and its length when sliding), so each is reused only by its own kind.
#[derive(Debug, Clone, Copy, Default)]
struct Jacobians {
    stick: Option<HeldJacobian>,
    slip: Option<HeldJacobian>,
}

/// A step of the loading path smaller than this that fails is an error, mm.
const MIN_STEP_MM: f64 = 0.02;

/// One quasi-static step: the plate moves by `step` (mm) from `at`. The tip first tries to stay
/// on its point of the plate; if that takes a tangential force outside the friction cone it
/// slides.
fn contact_step(
    config: &RodConfig,
    base: &RodBase,
    at: &Rest,
    step: Vec3,
    pose: &PlatePose,
    friction: f64,
) -> Result<Rest, ContactError> {
    let n = pose.normal;
    let [e1, e2] = pose.axes;
    let anchor = at.anchor + step;
    let stick = rod::solve_held(
        config,
        base,
        &|force| (force, anchor),
        HeldStart {
            parameters: at.force,
            base_moment_n_mm: at.base_moment,
            jacobian: at.jacobians.stick,
        },
        [1e-5; 3],
    );
    let stick_jacobian = match &stick {
        Ok(held) => held.jacobian,
        Err(_) => at.jacobians.stick,
    };
    let inside_cone = |f: Vec3| {
        let normal = f.dot(n);
        (f - n * normal).norm() <= friction * normal
    };
    if let Ok(held) = &stick
        && inside_cone(held.parameters)
    {
        return Ok(Rest {
            anchor,
            force: held.parameters,
            base_moment: Some(held.shape.base_moment_n_mm),
            jacobians: Jacobians {
                stick: stick_jacobian,
                slip: at.jacobians.slip,
            },
            state: ContactState::Stick,
        });
    }
    // Slip: unknowns (F_n, ψ, λ). The tangential force μ·F_n points along u(ψ) in the plate,
    // and the tip comes to rest λ behind the anchor, against it: q = anchor - λ·u.
    let direction = |psi: f64| e1 * psi.cos() + e2 * psi.sin();
    let force_of = |x: Vec3| n * x.x() + direction(x.y()) * (friction * x.x());
    // The rod under the last force, then its compliance's probes from where that solve ended.
    let (last, end) = rod::solve_near(config, base, at.force, None)?;
    let tip = last.tip_mm();
    let tip_under = |force: Vec3| {
        rod::solve_near(config, base, force, Some(&end)).map(|(shape, _)| shape.tip_mm())
    };
    let model = TipModel {
        compliance: compliance(&tip_under, at.force, tip)?,
        tip,
        force: at.force,
    };
    // The tip slides against the tangential force sticking would have taken: look near its
    // direction when the stick solve gave one.
    let around = stick.ok().map(|held| {
        let t = held.parameters - n * held.parameters.dot(n);
        t.dot(e2).atan2(t.dot(e1))
    });
    let guess = slip_guess(&model, anchor, pose, friction, around);
    let held = rod::solve_held(
        config,
        base,
        &|x| (force_of(x), anchor - direction(x.y()) * x.z()),
        HeldStart {
            parameters: guess,
            base_moment_n_mm: at.base_moment,
            jacobian: at.jacobians.slip,
        },
        [1e-6, 1e-5, 1e-5],
    )
    .map_err(|e| match e {
        RodError::NotConverged { iterations, .. } => ContactError::NotConverged {
            state: "slip",
            iterations,
        },
        e => ContactError::Rod(e),
    })?;
    let x = held.parameters;
    if x.z() < -1e-4 || x.x() <= 0.0 {
        return Err(ContactError::NotConverged {
            state: "slip",
            iterations: held.shape.newton_iterations,
        });
    }
    Ok(Rest {
        anchor: anchor - direction(x.y()) * x.z(),
        force: force_of(x),
        base_moment: Some(held.shape.base_moment_n_mm),
        jacobians: Jacobians {
            stick: stick_jacobian,
            slip: held.jacobian,
        },
        state: ContactState::Slip,
    })
}

fn to_na(v: Vec3) -> Vector3<f64> {
    Vector3::new(v.0[0], v.0[1], v.0[2])
}

/// The tip's position to first order about a force: `tip + compliance·(F - force)`.
struct TipModel {
    /// `∂tip/∂F` there, mm/N.
    compliance: Matrix3<f64>,
    /// The tip there, mm.
    tip: Vec3,
    /// The force, N.
    force: Vec3,
}

/// The tip's compliance at `force` (where the tip is at `tip`): `∂tip/∂F`, mm/N, by forward
/// differences.
fn compliance(
    tip_under: &dyn Fn(Vec3) -> Result<Vec3, RodError>,
    force: Vec3,
    tip: Vec3,
) -> Result<Matrix3<f64>, RodError> {
    const STEP_N: f64 = 1e-5;
    let mut c = Matrix3::zeros();
    for j in 0..3 {
        let mut probe = force;
        probe.0[j] += STEP_N;
        c.set_column(j, &to_na((tip_under(probe)? - tip) / STEP_N));
    }
    Ok(c)
}

/// A first guess `(F_n, ψ, λ)` of a slip step, from the tip's compliance at the last force: for
/// each direction ψ of the tangential force (every 5°) the normal force and the slip that best
/// carry the tip, to first order, to the plate; the direction that fits best (within ±45° of
/// `around` when given).
fn slip_guess(
    model: &TipModel,
    anchor: Vec3,
    pose: &PlatePose,
    friction: f64,
    around: Option<f64>,
) -> Vec3 {
    // tip + C·(F_n·(n + μu) - force) = anchor - λ·u, linear in (F_n, λ) for a given u.
    let TipModel {
        compliance,
        tip,
        force,
    } = model;
    let n = pose.normal;
    let [e1, e2] = pose.axes;
    let rhs = to_na(anchor - *tip) + compliance * to_na(*force);
    let mut best = (f64::INFINITY, Vec3::new(1e-3, 0.0, 0.0));
    for k in 0..72 {
        let psi = match around {
            Some(centre) => centre + (k as f64 - 36.0).to_radians() * 1.25,
            None => (k as f64 * 5.0).to_radians(),
        };
        let u = e1 * psi.cos() + e2 * psi.sin();
        let a =
            nalgebra::Matrix3x2::from_columns(&[compliance * to_na(n + u * friction), to_na(u)]);
        let Some(x) = (a.transpose() * a).lu().solve(&(a.transpose() * rhs)) else {
            continue;
        };
        let miss = (a * x - rhs).norm();
        if x[0] > 0.0 && x[1] >= 0.0 && miss < best.0 {
            best = (miss, Vec3::new(x[0], psi, x[1]));
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::scene::SceneSampling;

    fn bench_rod() -> (RodConfig, RodBase, RodShape, SensorPlate) {
        let sampling = SceneSampling::paper_bench();
        let plate = sampling
            .plate
            .clone()
            .expect("the paper's bench has a plate");
        let nominal = sampling.nominal_scene();
        let (config, base) = nominal.rod(&RodConfig::default());
        let rest = rod::solve(&config, &base, Vec3::ZERO).unwrap();
        (config, base, rest, plate)
    }

    #[test]
    fn a_stuck_tip_ends_on_the_plate_where_it_touched_and_the_force_makes_that_shape() {
        let (config, base, rest, plate) = bench_rod();
        let contact = PlateContact {
            tilt_deg: 0.0,
            tilt_azimuth_deg: 0.0,
            press_mm: 1.0,
            slide_mm: 0.5,
            slide_azimuth_deg: 30.0,
            state: ContactState::Free,
        };
        let pose = plate.pose(&base, &rest, &contact);
        // A rough plate: the tip does not slide.
        let solved = solve(
            &config,
            &base,
            &SensorPlate {
                friction: 1.5,
                ..plate.clone()
            },
            &pose,
            &contact,
        )
        .unwrap();
        assert_eq!(solved.state, ContactState::Stick);
        let rest_tip = rod::solve(&config, &base, Vec3::ZERO).unwrap().tip_mm();
        let a = 30f64.to_radians();
        let expected = rest_tip
            + pose.normal * (1.0 - plate.standoff_mm)
            + (pose.axes[0] * a.cos() + pose.axes[1] * a.sin()) * 0.5;
        assert!((solved.shape.tip_mm() - expected).norm() < 1e-5);
        // The force read from the contact is the one that bends the rod to it, and it pushes
        // the tip back.
        let again = rod::solve(&config, &base, solved.tip_force_n).unwrap();
        assert!((again.tip_mm() - expected).norm() < 1e-5);
        let f = solved.tip_force_n;
        assert!(f.dot(pose.normal) > 0.0, "{f:?}");
        assert!((f - pose.normal * f.dot(pose.normal)).norm() <= 1.5 * f.dot(pose.normal));
    }

    #[test]
    fn a_sliding_tip_keeps_its_tangential_force_on_the_friction_cone() {
        let (config, base, rest, plate) = bench_rod();
        let contact = PlateContact {
            tilt_deg: 0.0,
            tilt_azimuth_deg: 0.0,
            press_mm: 2.0,
            slide_mm: 3.0,
            slide_azimuth_deg: 100.0,
            state: ContactState::Free,
        };
        let pose = plate.pose(&base, &rest, &contact);
        let friction = 0.1;
        let solved = solve(
            &config,
            &base,
            &SensorPlate {
                friction,
                ..plate.clone()
            },
            &pose,
            &contact,
        )
        .unwrap();
        assert_eq!(solved.state, ContactState::Slip);
        let f = solved.tip_force_n;
        let normal = f.dot(pose.normal);
        let tangential = (f - pose.normal * normal).norm();
        assert!(
            (tangential - friction * normal).abs() < 1e-9,
            "{tangential} vs {}",
            friction * normal
        );
        // The tip is on the plate's face.
        let face = pose.point_mm + pose.normal * contact.press_mm;
        assert!((solved.shape.tip_mm() - face).dot(pose.normal).abs() < 1e-5);
    }

    #[test]
    fn a_plate_short_of_the_tip_leaves_it_unloaded() {
        let (config, base, rest, plate) = bench_rod();
        let contact = PlateContact {
            tilt_deg: 0.0,
            tilt_azimuth_deg: 0.0,
            press_mm: 0.5 * plate.standoff_mm,
            slide_mm: 2.0,
            slide_azimuth_deg: 0.0,
            state: ContactState::Free,
        };
        let pose = plate.pose(&base, &rest, &contact);
        let solved = solve(&config, &base, &plate, &pose, &contact).unwrap();
        assert_eq!(solved.state, ContactState::Free);
        assert_eq!(solved.tip_force_n, Vec3::ZERO);
    }

    #[test]
    fn the_actuators_travel_gives_forces_on_every_axis_within_the_sensors_range() {
        let sampling = SceneSampling::paper_bench();
        let (_, nominal_base) = sampling.nominal_scene().rod(&RodConfig::default());
        let (config, base, rest, plate) = bench_rod();
        assert_eq!(base, nominal_base);
        let mut rng = crate::simulator::scene::sample_rng(1, 0);
        let mut forces = Vec::new();
        let draws = 40;
        for _ in 0..draws {
            let scene = sampling.sample(&mut rng);
            let (config_drawn, base_drawn) = scene.rod(&config);
            let contact = scene.plate.expect("a contact is drawn");
            let pose = plate.pose(&base, &rest, &contact);
            if let Ok(solved) = solve(&config_drawn, &base_drawn, &plate, &pose, &contact) {
                forces.push(solved.tip_force_n);
            }
        }
        assert!(
            forces.len() * 10 >= draws * 8,
            "{} of {draws} solved",
            forces.len()
        );
        for axis in 0..3 {
            let values: Vec<f64> = forces.iter().map(|f| f.0[axis]).collect();
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64)
                .sqrt();
            assert!(sd > 0.01, "axis {axis}: sd {sd} N");
        }
        assert!(forces.iter().all(|f| f.norm() <= plate.max_force_n));
    }

    #[test]
    fn unusable_plates_are_refused_naming_the_setting() {
        let length = 50.0;
        let plate = SensorPlate::bench();
        assert_eq!(plate.check(length), Ok(()));
        let through = SensorPlate {
            standoff_mm: -1.0,
            ..plate.clone()
        };
        assert!(through.check(length).unwrap_err().contains("standoff_mm"));
        let short = SensorPlate {
            press_mm: [0.0, 0.5],
            ..plate.clone()
        };
        let why = short.check(length).unwrap_err();
        assert!(why.contains("cannot reach"), "{why}");
        let deep = SensorPlate {
            press_mm: [1.0, 30.0],
            ..plate.clone()
        };
        assert!(
            deep.check(length)
                .unwrap_err()
                .contains("through the plate")
        );
        let reversed = SensorPlate {
            slide_mm: [2.0, -2.0],
            ..plate
        };
        assert!(reversed.check(length).unwrap_err().contains("slide_mm"));
    }
}
