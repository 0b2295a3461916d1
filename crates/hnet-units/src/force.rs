//! The tip force: the one type in which the network, the twin, the rod fit, the dataset format,
//! the command-line tool and the page pass a force at the catheter's tip.

use core::fmt;
use core::ops::{Index, IndexMut, Sub};

use serde::{Deserialize, Serialize};

/// A force at the catheter's tip `(Fx, Fy, Fz)`, in newtons, in the twin's world frame (x and y
/// horizontal, z up; docs/twin.md): what the network's force head estimates, the rod fit reads
/// from the masks, a label records and the twin applies to its rod.
///
/// Held in single precision, the network's (a newton's ten-millionth is far below any force the
/// views can tell apart); the rod's mechanics convert to their own `f64` vectors. Files store it
/// as the array `[fx, fy, fz]`, as they did before this type existed.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct TipForce([f32; 3]);

impl TipForce {
    /// No force.
    pub const ZERO: Self = Self([0.0; 3]);

    /// The axes' names, in order: `Fx`, `Fy`, `Fz`.
    pub const AXES: [&'static str; 3] = ["Fx", "Fy", "Fz"];

    /// `(fx, fy, fz)`, N.
    pub const fn new(fx: f32, fy: f32, fz: f32) -> Self {
        Self([fx, fy, fz])
    }

    /// From `[Fx, Fy, Fz]`, N.
    pub const fn from_newtons(newtons: [f32; 3]) -> Self {
        Self(newtons)
    }

    /// From `[Fx, Fy, Fz]` in double precision, N (the rod's mechanics and fit), rounded to
    /// single.
    pub fn from_f64(newtons: [f64; 3]) -> Self {
        Self(newtons.map(|f| f as f32))
    }

    /// `[Fx, Fy, Fz]`, N.
    pub const fn newtons(self) -> [f32; 3] {
        self.0
    }

    /// `[Fx, Fy, Fz]` in double precision, N.
    pub fn to_f64(self) -> [f64; 3] {
        self.0.map(f64::from)
    }

    /// Fx, N.
    pub const fn x(self) -> f32 {
        self.0[0]
    }

    /// Fy, N.
    pub const fn y(self) -> f32 {
        self.0[1]
    }

    /// Fz, N.
    pub const fn z(self) -> f32 {
        self.0[2]
    }

    /// Its magnitude |F|, N: the one formula of the CLI, the DICOM force trace and the page.
    pub fn magnitude(self) -> f32 {
        self.0.iter().map(|f| f * f).sum::<f32>().sqrt()
    }

    /// Its largest component's magnitude, N (how far an estimate is off on its worst axis).
    pub fn max_abs(self) -> f32 {
        self.0.iter().fold(0.0, |m, f| m.max(f.abs()))
    }

    /// Whether every component is a finite number.
    pub fn is_finite(self) -> bool {
        self.0.iter().all(|f| f.is_finite())
    }

    /// Each component through `f`.
    pub fn map(self, f: impl FnMut(f32) -> f32) -> Self {
        Self(self.0.map(f))
    }
}

impl Index<usize> for TipForce {
    type Output = f32;

    /// Component `axis` (0 = Fx, 1 = Fy, 2 = Fz), N.
    fn index(&self, axis: usize) -> &f32 {
        &self.0[axis]
    }
}

impl IndexMut<usize> for TipForce {
    fn index_mut(&mut self, axis: usize) -> &mut f32 {
        &mut self.0[axis]
    }
}

impl Sub for TipForce {
    type Output = Self;

    /// The per-axis difference, N (an estimate's error: `estimate - truth`).
    fn sub(self, other: Self) -> Self {
        Self(core::array::from_fn(|i| self.0[i] - other.0[i]))
    }
}

impl From<[f32; 3]> for TipForce {
    fn from(newtons: [f32; 3]) -> Self {
        Self(newtons)
    }
}

impl From<TipForce> for [f32; 3] {
    fn from(force: TipForce) -> Self {
        force.0
    }
}

impl fmt::Display for TipForce {
    /// `(fx, fy, fz) N`, to the precision asked (3 decimals by default).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let digits = f.precision().unwrap_or(3);
        let [x, y, z] = self.0;
        write!(f, "({x:.digits$}, {y:.digits$}, {z:.digits$}) N")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_keep_the_bare_array() {
        let force = TipForce::new(0.1, -0.25, 0.001);
        assert_eq!(serde_json::to_string(&force).unwrap(), "[0.1,-0.25,0.001]");
        let read: TipForce = serde_json::from_str("[0.1, -0.25, 1e-3]").unwrap();
        assert_eq!(read, force);
        assert!(serde_json::from_str::<TipForce>("[0.1, 0.2]").is_err());
    }

    #[test]
    fn magnitude_difference_and_display() {
        let force = TipForce::new(0.3, 0.0, -0.4);
        assert!((force.magnitude() - 0.5).abs() < 1e-6);
        assert_eq!(force - force, TipForce::ZERO);
        assert_eq!(force[2], -0.4);
        assert_eq!(format!("{force:.2}"), "(0.30, 0.00, -0.40) N");
        assert_eq!(TipForce::from_f64(force.to_f64()), force);
    }
}
