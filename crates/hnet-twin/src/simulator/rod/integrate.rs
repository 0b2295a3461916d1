//! The rod's equations integrated along its arc length (RK4) from a base moment: the shooting
//! step that [`super::solve`] and [`super::solve_held`] search the base moment with.

use super::{RodBase, RodConfig, RodShape};
use crate::vec3::{Mat3, Quat, Vec3};

/// One integration state: position, orientation, internal moment (world frame).
#[derive(Clone, Copy)]
struct State {
    p: Vec3,
    q: [f64; 4],
    m: Vec3,
}

struct Derivative {
    p: Vec3,
    q: [f64; 4],
    m: Vec3,
}

impl State {
    fn advanced(&self, d: &Derivative, h: f64) -> State {
        let mut q = self.q;
        for (qi, di) in q.iter_mut().zip(d.q) {
            *qi += h * di;
        }
        State {
            p: self.p + d.p * h,
            q,
            m: self.m + d.m * h,
        }
    }
}

pub(super) struct Problem<'a> {
    pub(super) config: &'a RodConfig,
    pub(super) base: &'a RodBase,
    pub(super) tip_force: Vec3,
    pub(super) weight: Vec3,
    pub(super) stiffness: Vec3,
}

impl Problem<'_> {
    /// The state's derivative at arc length `s`, where the rod is `factor` times as stiff as
    /// its base stiffness.
    fn derivative(&self, s: f64, y: &State, factor: f64) -> Derivative {
        let q = Quat(y.q);
        let rotation = q.to_matrix();
        let tangent = rotation.column(2);
        let n = self.tip_force + self.weight * (self.config.length_mm - s);
        let m_body = rotation.transpose() * y.m;
        let u = Vec3::new(
            m_body[0] / (factor * self.stiffness[0]),
            m_body[1] / (factor * self.stiffness[1]),
            m_body[2] / (factor * self.stiffness[2]),
        ) + self.config.intrinsic_curvature(s);
        Derivative {
            p: tangent,
            q: q.derivative(u),
            m: -tangent.cross(n),
        }
    }

    /// Integrates from the base with base moment `m0`; returns what the tip's moment lacks of the
    /// tip load's and, if asked, the centreline.
    pub(super) fn shoot(&self, m0: Vec3, record: bool) -> (Vec3, Option<RodShape>) {
        let shot = self.integrate(m0, record);
        (shot.tip_moment_lack, shot.shape)
    }

    /// Integrates from the base with base moment `m0`.
    pub(super) fn integrate(&self, m0: Vec3, record: bool) -> Shot {
        let steps = self.config.steps;
        let h = self.config.length_mm / steps as f64;
        let mut y = State {
            p: self.base.position_mm,
            q: Quat::from_matrix(&self.base.orientation).0,
            m: m0,
        };
        let mut shape = record.then(|| RodShape {
            arc_mm: Vec::with_capacity(steps + 1),
            points_mm: Vec::with_capacity(steps + 1),
            tangents: Vec::with_capacity(steps + 1),
            base_moment_n_mm: m0,
            newton_iterations: 0,
            residual_n_mm: 0.0,
        });
        let push = |shape: &mut Option<RodShape>, s: f64, y: &State| {
            if let Some(shape) = shape {
                shape.arc_mm.push(s);
                shape.points_mm.push(y.p);
                shape.tangents.push(Quat(y.q).to_matrix().column(2));
            }
        };
        push(&mut shape, 0.0, &y);
        for i in 0..steps {
            let s = i as f64 * h;
            // One stiffness per step, the one at its middle: a stiff segment that starts or
            // ends on a step boundary then covers exactly its steps.
            let factor = self.config.stiffness_factor(s + h / 2.0);
            let k1 = self.derivative(s, &y, factor);
            let k2 = self.derivative(s + h / 2.0, &y.advanced(&k1, h / 2.0), factor);
            let k3 = self.derivative(s + h / 2.0, &y.advanced(&k2, h / 2.0), factor);
            let k4 = self.derivative(s + h, &y.advanced(&k3, h), factor);
            y.p += (k1.p + k2.p * 2.0 + k3.p * 2.0 + k4.p) * (h / 6.0);
            y.m += (k1.m + k2.m * 2.0 + k3.m * 2.0 + k4.m) * (h / 6.0);
            for j in 0..4 {
                y.q[j] += h / 6.0 * (k1.q[j] + 2.0 * k2.q[j] + 2.0 * k3.q[j] + k4.q[j]);
            }
            y.q = Quat(y.q).normalized().0;
            push(&mut shape, s + h, &y);
        }
        let tip_frame = Quat(y.q).to_matrix();
        let offset = tip_frame * self.config.tip_load_offset_mm;
        Shot {
            tip_moment_lack: y.m - offset.cross(self.tip_force),
            tip_mm: y.p,
            tip_frame,
            shape,
        }
    }
}

/// One integration from the base.
pub(super) struct Shot {
    /// What the tip's moment lacks of the tip load's, N·mm (zero when the boundary condition
    /// holds).
    pub(super) tip_moment_lack: Vec3,
    /// The tip's position, mm.
    pub(super) tip_mm: Vec3,
    /// The tip's frame (columns: the cross-section's axes and the tangent).
    pub(super) tip_frame: Mat3,
    /// The centreline, when asked for.
    pub(super) shape: Option<RodShape>,
}

/// Solves `a x = b` for a 3x3 system by Gaussian elimination with partial pivoting.
pub(super) fn solve3(a: [[f64; 3]; 3], b: Vec3) -> Option<Vec3> {
    let mut m = [[0.0; 4]; 3];
    for i in 0..3 {
        m[i][..3].copy_from_slice(&a[i]);
        m[i][3] = b[i];
    }
    for col in 0..3 {
        let pivot = (col..3).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[pivot][col].abs() < 1e-300 {
            return None;
        }
        m.swap(col, pivot);
        let pivot_row = m[col];
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / pivot_row[col];
            for (value, pivot_value) in row.iter_mut().zip(pivot_row).skip(col) {
                *value -= f * pivot_value;
            }
        }
    }
    let mut x = [0.0; 3];
    for i in (0..3).rev() {
        let tail: f64 = (i + 1..3).map(|k| m[i][k] * x[k]).sum();
        x[i] = (m[i][3] - tail) / m[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(Vec3(x))
}
