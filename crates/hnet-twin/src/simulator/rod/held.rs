//! A rod whose tip is held where a load puts it: the shooting problem of [`super::solve`] with
//! the tip's position as a condition and the load as an unknown (the sensor plate's contact,
//! [`crate::simulator::sensor_plate`]).

use super::*;

/// A rod whose tip is held: [`solve_held`]'s solution.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldRod {
    /// The centreline.
    pub shape: RodShape,
    /// The load parameters found.
    pub parameters: Vec3,
    /// The last Jacobian of the six conditions, for the next solve of the same kind of hold
    /// along a path ([`HeldStart::jacobian`]).
    pub jacobian: Option<HeldJacobian>,
}

/// The Jacobian of a held solve's six conditions (the tip's moment over its scale, the tip's miss
/// in mm) with respect to the base moment and the three load parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldJacobian {
    matrix: nalgebra::SMatrix<f64, 6, 6>,
    /// The moment scale its first three rows are divided by, N·mm.
    moment_scale: f64,
}

/// Where [`solve_held`] starts.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HeldStart {
    /// The first load parameters θ.
    pub parameters: Vec3,
    /// The base moment of a nearby solution, N·mm, when known.
    pub base_moment_n_mm: Option<Vec3>,
    /// The last Jacobian of a nearby solve of the same hold (the same parameters' meaning), when
    /// known: reused while a full step halves the residual (the chord method), instead of seven
    /// integrations an iteration.
    pub jacobian: Option<HeldJacobian>,
}

/// Solves the rod clamped at `base` whose tip load and tip position both depend on three
/// parameters θ: `load(θ) = (tip force N, where the tip must end mm)`. A held tip (a contact)
/// gives the force as an unknown: θ is the force and the target fixed (sticking), or the normal
/// force and a slide on a plate (sliding). Newton's method on the six unknowns (the base moment
/// and θ) against the six conditions (no tip moment, the tip on its target), by shooting with a
/// forward-difference Jacobian of steps `step` for θ, and a backtracking line search, from
/// `start`.
pub fn solve_held(
    config: &RodConfig,
    base: &RodBase,
    load: &dyn Fn(Vec3) -> (Vec3, Vec3),
    start: HeldStart,
    step: [f64; 3],
) -> Result<HeldRod, RodError> {
    use nalgebra::{SMatrix, SVector};
    config.validate()?;
    let ei = config.bending_stiffness_n_mm2();
    let stiffness = Vec3::new(ei, ei, config.torsional_stiffness_n_mm2());
    let weight = config.weight_per_mm();
    let length = config.length_mm;
    let HeldStart {
        parameters: mut theta,
        base_moment_n_mm: m0,
        jacobian: known,
    } = start;
    let mut m0 = match m0 {
        Some(m0) => m0,
        None => solve(config, base, load(theta).0)?.base_moment_n_mm,
    };
    let moment_scale = (load(theta).0.norm() * length).max(ei / length);
    // Residual: tip moment over its scale, tip miss in mm.
    let residual = |m0: Vec3, theta: Vec3| -> SVector<f64, 6> {
        let (force, target) = load(theta);
        let problem = Problem {
            config,
            base,
            tip_force: force,
            weight,
            stiffness,
        };
        let shot = problem.integrate(m0, false);
        let (m, miss) = (shot.tip_moment_lack, shot.tip_mm - target);
        SVector::<f64, 6>::from_column_slice(&[
            m[0] / moment_scale,
            m[1] / moment_scale,
            m[2] / moment_scale,
            miss[0],
            miss[1],
            miss[2],
        ])
    };
    const TOLERANCE: f64 = 1e-9;
    let mut r = residual(m0, theta);
    let mut norm = r.norm();
    let mut iterations = 0;
    // The nearby solve's Jacobian, its moment rows rescaled to this solve's moment scale.
    let mut jacobian = known.map(|known| {
        let mut matrix = known.matrix;
        let rescale = known.moment_scale / moment_scale;
        matrix.fixed_rows_mut::<3>(0).scale_mut(rescale);
        matrix
    });
    // Whether `jacobian` was computed in this solve.
    let mut fresh = false;
    while norm > TOLERANCE {
        if iterations == config.max_newton_iterations || !norm.is_finite() {
            return Err(RodError::NotConverged {
                iterations,
                residual_n_mm: norm * moment_scale,
                tolerance_n_mm: TOLERANCE * moment_scale,
            });
        }
        iterations += 1;
        if let Some(known) = jacobian.filter(|_| !fresh) {
            // The chord step: kept at full length only where it halves the residual.
            if let Some(delta) = known.lu().solve(&-r) {
                let m = m0 + Vec3([delta[0], delta[1], delta[2]]);
                let t = theta + Vec3([delta[3], delta[4], delta[5]]);
                let trial = residual(m, t);
                if trial.norm().is_finite() && trial.norm() <= CHORD_KEPT_BELOW * norm {
                    (m0, theta, r, norm) = (m, t, trial, trial.norm());
                    continue;
                }
            }
        }
        let mut fd = SMatrix::<f64, 6, 6>::zeros();
        for j in 0..6 {
            let (mut m, mut t) = (m0, theta);
            let h = if j < 3 {
                let h = 1e-7 * m0.max_abs().max(moment_scale);
                m.0[j] += h;
                h
            } else {
                t.0[j - 3] += step[j - 3];
                step[j - 3]
            };
            fd.set_column(j, &((residual(m, t) - r) / h));
        }
        jacobian = Some(fd);
        fresh = true;
        let Some(delta) = fd.lu().solve(&-r) else {
            return Err(RodError::NotConverged {
                iterations,
                residual_n_mm: norm * moment_scale,
                tolerance_n_mm: TOLERANCE * moment_scale,
            });
        };
        let mut alpha = 1.0;
        loop {
            let m = m0 + Vec3([delta[0], delta[1], delta[2]]) * alpha;
            let t = theta + Vec3([delta[3], delta[4], delta[5]]) * alpha;
            let trial = residual(m, t);
            if trial.norm().is_finite() && trial.norm() < (1.0 - 1e-4 * alpha) * norm {
                (m0, theta, r, norm) = (m, t, trial, trial.norm());
                break;
            }
            alpha /= 2.0;
            if alpha < 1e-6 {
                return Err(RodError::NotConverged {
                    iterations,
                    residual_n_mm: norm * moment_scale,
                    tolerance_n_mm: TOLERANCE * moment_scale,
                });
            }
        }
    }
    let problem = Problem {
        config,
        base,
        tip_force: load(theta).0,
        weight,
        stiffness,
    };
    let mut shape = problem.integrate(m0, true).shape.expect("recorded");
    shape.newton_iterations = iterations;
    shape.residual_n_mm = r.fixed_rows::<3>(0).norm() * moment_scale;
    Ok(HeldRod {
        shape,
        parameters: theta,
        jacobian: jacobian.map(|matrix| HeldJacobian {
            matrix,
            moment_scale,
        }),
    })
}
