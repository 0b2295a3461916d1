//! Small 3D vector, rotation and quaternion types for the rod and the C-arm.
//!
//! Lengths are whatever the caller uses (the twin uses millimetres throughout).

use core::ops::{Add, AddAssign, Div, Index, Mul, Neg, Sub};

use hnet_units::TipForce;
use serde::{Deserialize, Serialize};

/// A 3D vector.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vec3(pub [f64; 3]);

impl Vec3 {
    /// The zero vector.
    pub const ZERO: Self = Self([0.0; 3]);
    /// Unit x.
    pub const X: Self = Self([1.0, 0.0, 0.0]);
    /// Unit y.
    pub const Y: Self = Self([0.0, 1.0, 0.0]);
    /// Unit z.
    pub const Z: Self = Self([0.0, 0.0, 1.0]);

    /// A vector from its components.
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self([x, y, z])
    }

    /// x component.
    pub fn x(self) -> f64 {
        self.0[0]
    }

    /// y component.
    pub fn y(self) -> f64 {
        self.0[1]
    }

    /// z component.
    pub fn z(self) -> f64 {
        self.0[2]
    }

    /// Dot product.
    pub fn dot(self, o: Self) -> f64 {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }

    /// Cross product.
    pub fn cross(self, o: Self) -> Self {
        let [a, b, c] = self.0;
        let [d, e, f] = o.0;
        Self([b * f - c * e, c * d - a * f, a * e - b * d])
    }

    /// Euclidean length.
    pub fn norm(self) -> f64 {
        self.dot(self).sqrt()
    }

    /// This vector scaled to unit length (the zero vector stays zero).
    pub fn normalized(self) -> Self {
        let n = self.norm();
        if n > 0.0 { self / n } else { self }
    }

    /// Whether every component is zero.
    pub fn is_zero(&self) -> bool {
        self.0 == [0.0; 3]
    }

    /// Largest absolute component.
    pub fn max_abs(self) -> f64 {
        self.0.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    }

    /// Any unit vector perpendicular to this one.
    pub fn any_perpendicular(self) -> Self {
        let helper = if self.x().abs() < 0.9 {
            Self::X
        } else {
            Self::Y
        };
        self.cross(helper).normalized()
    }
}

impl From<TipForce> for Vec3 {
    /// A tip force as the rod's mechanics hold it, N.
    fn from(force: TipForce) -> Self {
        Self(force.to_f64())
    }
}

impl From<Vec3> for TipForce {
    /// A force the rod's mechanics found, N, rounded to the tip force's single precision.
    fn from(force_n: Vec3) -> Self {
        TipForce::from_f64(force_n.0)
    }
}

impl Index<usize> for Vec3 {
    type Output = f64;
    fn index(&self, i: usize) -> &f64 {
        &self.0[i]
    }
}

impl Add for Vec3 {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }
}

impl AddAssign for Vec3 {
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}

impl Sub for Vec3 {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self([self.0[0] - o.0[0], self.0[1] - o.0[1], self.0[2] - o.0[2]])
    }
}

impl Neg for Vec3 {
    type Output = Self;
    fn neg(self) -> Self {
        Self([-self.0[0], -self.0[1], -self.0[2]])
    }
}

impl Mul<f64> for Vec3 {
    type Output = Self;
    fn mul(self, k: f64) -> Self {
        Self([self.0[0] * k, self.0[1] * k, self.0[2] * k])
    }
}

impl Div<f64> for Vec3 {
    type Output = Self;
    fn div(self, k: f64) -> Self {
        Self([self.0[0] / k, self.0[1] / k, self.0[2] / k])
    }
}

/// A 3x3 matrix, row-major. Rotations map body coordinates to world coordinates; their columns
/// are the body axes expressed in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mat3(pub [[f64; 3]; 3]);

impl Mat3 {
    /// The identity.
    pub const IDENTITY: Self = Self([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// The matrix whose columns are `a`, `b`, `c`.
    pub fn from_columns(a: Vec3, b: Vec3, c: Vec3) -> Self {
        Self([[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]])
    }

    /// Column `i`.
    pub fn column(&self, i: usize) -> Vec3 {
        Vec3([self.0[0][i], self.0[1][i], self.0[2][i]])
    }

    /// Row `i`.
    pub fn row(&self, i: usize) -> Vec3 {
        Vec3(self.0[i])
    }

    /// Rotation by `angle` radians about the unit `axis` (right-handed).
    pub fn rotation(axis: Vec3, angle: f64) -> Self {
        let [x, y, z] = axis.normalized().0;
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        Self([
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ])
    }

    /// The transpose (the inverse of a rotation).
    pub fn transpose(&self) -> Self {
        let m = &self.0;
        Self([
            [m[0][0], m[1][0], m[2][0]],
            [m[0][1], m[1][1], m[2][1]],
            [m[0][2], m[1][2], m[2][2]],
        ])
    }
}

impl Mul<Vec3> for Mat3 {
    type Output = Vec3;
    fn mul(self, v: Vec3) -> Vec3 {
        Vec3([self.row(0).dot(v), self.row(1).dot(v), self.row(2).dot(v)])
    }
}

impl Mul for Mat3 {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        let mut out = [[0.0; 3]; 3];
        for (i, row) in out.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = self.row(i).dot(o.column(j));
            }
        }
        Self(out)
    }
}

/// A unit quaternion `w + xi + yj + zk` representing a rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quat(pub [f64; 4]);

impl Quat {
    /// The quaternion of a rotation matrix.
    pub fn from_matrix(m: &Mat3) -> Self {
        let r = &m.0;
        let trace = r[0][0] + r[1][1] + r[2][2];
        let q = if trace > 0.0 {
            let s = (trace + 1.0).sqrt() * 2.0;
            [
                0.25 * s,
                (r[2][1] - r[1][2]) / s,
                (r[0][2] - r[2][0]) / s,
                (r[1][0] - r[0][1]) / s,
            ]
        } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
            let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
            [
                (r[2][1] - r[1][2]) / s,
                0.25 * s,
                (r[0][1] + r[1][0]) / s,
                (r[0][2] + r[2][0]) / s,
            ]
        } else if r[1][1] > r[2][2] {
            let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
            [
                (r[0][2] - r[2][0]) / s,
                (r[0][1] + r[1][0]) / s,
                0.25 * s,
                (r[1][2] + r[2][1]) / s,
            ]
        } else {
            let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
            [
                (r[1][0] - r[0][1]) / s,
                (r[0][2] + r[2][0]) / s,
                (r[1][2] + r[2][1]) / s,
                0.25 * s,
            ]
        };
        Self(q).normalized()
    }

    /// The rotation matrix.
    pub fn to_matrix(self) -> Mat3 {
        let [w, x, y, z] = self.0;
        Mat3([
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ])
    }

    /// Scaled to unit norm.
    pub fn normalized(self) -> Self {
        let n = self.0.iter().map(|v| v * v).sum::<f64>().sqrt();
        Self(self.0.map(|v| v / n))
    }

    /// The rotation vector (unit axis times angle in `[0, π]`, rad) of this rotation.
    pub fn rotation_vector(self) -> Vec3 {
        let [w, x, y, z] = self.normalized().0;
        // q and -q are the same rotation: take the one with w >= 0, whose angle is at most π.
        let sign = if w < 0.0 { -1.0 } else { 1.0 };
        let v = Vec3([x, y, z]) * sign;
        let half_sin = v.norm();
        if half_sin < 1e-15 {
            return Vec3::ZERO;
        }
        v * (2.0 * half_sin.atan2(w * sign) / half_sin)
    }

    /// Derivative `q' = ½ q ⊗ (0, u)` for a body-frame angular rate `u`.
    pub fn derivative(self, u: Vec3) -> [f64; 4] {
        let [w, x, y, z] = self.0;
        let [a, b, c] = u.0;
        [
            0.5 * (-x * a - y * b - z * c),
            0.5 * (w * a + y * c - z * b),
            0.5 * (w * b + z * a - x * c),
            0.5 * (w * c + x * b - y * a),
        ]
    }

    /// Rotates a body vector into the world frame.
    pub fn rotate(self, v: Vec3) -> Vec3 {
        self.to_matrix() * v
    }

    /// Rotates a world vector into the body frame.
    pub fn inverse_rotate(self, v: Vec3) -> Vec3 {
        self.to_matrix().transpose() * v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).max_abs() < 1e-12
    }

    #[test]
    fn rotation_matrices_and_quaternions_agree() {
        let m = Mat3::rotation(Vec3::new(1.0, 2.0, -0.5), 0.7);
        let back = Quat::from_matrix(&m).to_matrix();
        for i in 0..3 {
            assert!(close(m.column(i), back.column(i)));
        }
        // A quarter turn about z takes x to y.
        let q = Mat3::rotation(Vec3::Z, core::f64::consts::FRAC_PI_2);
        assert!(close(q * Vec3::X, Vec3::Y));
        assert!(close((q.transpose() * q) * Vec3::X, Vec3::X));
        // The rotation vector is the axis times the angle, up to a half turn.
        let axis = Vec3::new(1.0, 2.0, -0.5).normalized();
        for angle in [0.0, 0.7, 3.0, core::f64::consts::PI] {
            let w = Quat::from_matrix(&Mat3::rotation(axis, angle)).rotation_vector();
            assert!((w - axis * angle).max_abs() < 1e-9, "{angle}: {w:?}");
        }
    }

    #[test]
    fn cross_product_is_right_handed() {
        assert!(close(Vec3::X.cross(Vec3::Y), Vec3::Z));
        assert!(close(
            Vec3::Z.any_perpendicular().cross(Vec3::Z).cross(Vec3::Z),
            -Vec3::Z.any_perpendicular()
        ));
    }
}
