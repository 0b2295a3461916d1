//! The 3D view's camera: it orbits a target point (yaw about the patient's long axis, pitch
//! about the left-right axis, the same convention as a C-arm's primary and secondary angles, so
//! that at 0°/0° the 3D view looks as view A does and at 90°/0° as the lateral view B), zooms,
//! and projects world points (mm) to canvas pixels orthographically or in perspective.

use hnet_twin::simulator::carm::CArm;
use hnet_twin::vec3::{Mat3, Vec3};
use hnet_units::ImageSize;

/// How depth is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Projection {
    /// Parallel lines stay parallel; sizes do not change with depth (for judging shape).
    Orthographic,
    /// Nearer is larger, from an eye [`PERSPECTIVE_DISTANCE`] framing radii from the target.
    Perspective,
}

/// The perspective eye's distance from the target, in framing radii.
pub const PERSPECTIVE_DISTANCE: f64 = 4.0;

/// Zoom limits (1 frames the scene).
pub const ZOOM_RANGE: [f64; 2] = [0.25, 20.0];

/// The orbiting camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrbitCamera {
    /// Rotation about the world's z axis (cranial), degrees; 0 looks along +y like view A.
    pub yaw_deg: f64,
    /// Tilt towards the head, degrees, within ±89°.
    pub pitch_deg: f64,
    /// Magnification; 1 fits a sphere of [`OrbitCamera::radius_mm`] in the canvas.
    pub zoom: f64,
    /// Orthographic or perspective.
    pub projection: Projection,
    /// The point orbited, mm (world frame); it is drawn at the canvas' centre.
    pub target_mm: [f64; 3],
    /// Radius of the sphere that zoom 1 fits in the canvas, mm.
    pub radius_mm: f64,
}

impl Default for OrbitCamera {
    /// An oblique view (30° LAO, 20° cranial) of a sphere of 100 mm around the isocentre.
    fn default() -> Self {
        Self {
            yaw_deg: 30.0,
            pitch_deg: 20.0,
            zoom: 1.0,
            projection: Projection::Perspective,
            target_mm: [0.0; 3],
            radius_mm: 100.0,
        }
    }
}

impl OrbitCamera {
    /// This camera aimed at `focus` (its centre is the target) and framing every point of
    /// `points` (and of `focus`) at zoom 1; the angles, zoom and projection are kept.
    pub fn framing(self, focus: &[[f64; 3]], points: &[[f64; 3]]) -> Self {
        if focus.is_empty() {
            return self;
        }
        let n = focus.len() as f64;
        let target = [0, 1, 2].map(|i| focus.iter().map(|p| p[i]).sum::<f64>() / n);
        let radius = focus
            .iter()
            .chain(points)
            .map(|p| (Vec3(*p) - Vec3(target)).norm())
            .fold(1.0, f64::max);
        Self {
            target_mm: target,
            radius_mm: radius,
            ..self
        }
    }

    /// Rows: the canvas' right and down directions and the viewing direction, in world axes.
    pub fn axes(&self) -> Mat3 {
        // A C-arm at these angles looks along its beam with u to the right and v down.
        CArm::cardiac(self.yaw_deg, self.pitch_deg, ImageSize::square(1)).rotation()
    }

    /// Turned by `yaw` and `pitch` degrees (pitch kept within ±89°, yaw within ±180°).
    pub fn rotated(self, yaw_deg: f64, pitch_deg: f64) -> Self {
        let yaw = (self.yaw_deg + yaw_deg + 180.0).rem_euclid(360.0) - 180.0;
        Self {
            yaw_deg: yaw,
            pitch_deg: (self.pitch_deg + pitch_deg).clamp(-89.0, 89.0),
            ..self
        }
    }

    /// Zoomed by `factor`, within [`ZOOM_RANGE`].
    pub fn zoomed(self, factor: f64) -> Self {
        Self {
            zoom: (self.zoom * factor).clamp(ZOOM_RANGE[0], ZOOM_RANGE[1]),
            ..self
        }
    }

    /// The other projection.
    pub fn toggled_projection(self) -> Self {
        Self {
            projection: match self.projection {
                Projection::Orthographic => Projection::Perspective,
                Projection::Perspective => Projection::Orthographic,
            },
            ..self
        }
    }

    /// Where `point_mm` is drawn on a square canvas of `side` pixels; `None` for a point at or
    /// behind the perspective eye.
    pub fn project(&self, point_mm: [f64; 3], side: f64) -> Option<[f64; 2]> {
        let axes = self.axes();
        let rel = Vec3(point_mm) - Vec3(self.target_mm);
        let (x, y, depth) = (
            axes.row(0).dot(rel),
            axes.row(1).dot(rel),
            axes.row(2).dot(rel),
        );
        // Zoom 1: the framing sphere fills 90 % of the canvas.
        let scale = self.zoom * 0.45 * side / self.radius_mm;
        let k = match self.projection {
            Projection::Orthographic => 1.0,
            Projection::Perspective => {
                let eye = PERSPECTIVE_DISTANCE * self.radius_mm;
                if eye + depth <= 1e-6 * eye {
                    return None;
                }
                // Unit magnification at the target's depth.
                eye / (eye + depth)
            }
        };
        Some([side / 2.0 + x * scale * k, side / 2.0 + y * scale * k])
    }
}

#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    const SIDE: f64 = 400.0;

    fn close(a: [f64; 2], b: [f64; 2]) -> bool {
        (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9
    }

    #[test]
    fn the_target_is_at_the_centre_and_the_frame_fills_the_canvas() {
        let camera = OrbitCamera {
            projection: Projection::Orthographic,
            ..OrbitCamera::default()
        }
        .framing(&[[10.0, 0.0, 0.0], [30.0, 0.0, 0.0]], &[[20.0, 0.0, 50.0]]);
        assert_eq!(camera.target_mm, [20.0, 0.0, 0.0]);
        assert_eq!(camera.radius_mm, 50.0);
        assert!(close(
            camera.project([20.0, 0.0, 0.0], SIDE).unwrap(),
            [200.0, 200.0]
        ));
        // A point one radius away across the view lands 45 % of the side from the centre.
        let front = OrbitCamera {
            yaw_deg: 0.0,
            pitch_deg: 0.0,
            ..camera
        };
        assert!(close(
            front.project([20.0, 0.0, 50.0], SIDE).unwrap(),
            [200.0, 20.0]
        ));
    }

    #[test]
    fn at_zero_angles_it_looks_like_view_a_and_at_90_like_view_b() {
        let front = OrbitCamera {
            yaw_deg: 0.0,
            pitch_deg: 0.0,
            projection: Projection::Orthographic,
            ..OrbitCamera::default()
        };
        // View A: the patient's left (+x) to the right, the head (+z) up.
        let left = front.project([10.0, 0.0, 0.0], SIDE).unwrap();
        let head = front.project([0.0, 0.0, 10.0], SIDE).unwrap();
        assert!(left[0] > 200.0 && (left[1] - 200.0).abs() < 1e-9);
        assert!(head[1] < 200.0 && (head[0] - 200.0).abs() < 1e-9);
        // Depth (+y, along the beam) does not move a point orthographically.
        assert!(close(
            front.project([0.0, 30.0, 0.0], SIDE).unwrap(),
            [200.0, 200.0]
        ));
        // View B (90° LAO) looks along +x: anterior (+y)... as the C-arm's own image axes.
        let side = front.rotated(90.0, 0.0);
        let b = CArm::cardiac(90.0, 0.0, ImageSize::square(224)).rotation();
        let p = side.project([0.0, 10.0, 0.0], SIDE).unwrap();
        assert!((p[0] - 200.0 - b.row(0).y() * 10.0 * 0.45 * SIDE / 100.0).abs() < 1e-9);
    }

    #[test]
    fn perspective_enlarges_what_is_near_and_hides_what_is_behind_the_eye() {
        let camera = OrbitCamera {
            yaw_deg: 0.0,
            pitch_deg: 0.0,
            ..OrbitCamera::default()
        };
        // Nearer the eye (-y, towards view A's source) is larger than farther.
        let near = camera.project([10.0, -50.0, 0.0], SIDE).unwrap()[0] - 200.0;
        let far = camera.project([10.0, 50.0, 0.0], SIDE).unwrap()[0] - 200.0;
        assert!(near > far && far > 0.0, "{near} {far}");
        // The target's depth is drawn as orthographically.
        let ortho = camera.toggled_projection();
        assert_eq!(ortho.projection, Projection::Orthographic);
        assert!(close(
            camera.project([10.0, 0.0, 5.0], SIDE).unwrap(),
            ortho.project([10.0, 0.0, 5.0], SIDE).unwrap()
        ));
        assert_eq!(camera.project([0.0, -400.0, 0.0], SIDE), None);
        assert!(ortho.project([0.0, -400.0, 0.0], SIDE).is_some());
    }

    #[test]
    fn rotation_and_zoom_stay_in_range() {
        let camera = OrbitCamera::default();
        assert_eq!(camera.rotated(0.0, 200.0).pitch_deg, 89.0);
        assert_eq!(camera.rotated(0.0, -200.0).pitch_deg, -89.0);
        assert!((camera.rotated(170.0, 0.0).yaw_deg + 160.0).abs() < 1e-9);
        assert_eq!(camera.zoomed(1e3).zoom, ZOOM_RANGE[1]);
        assert_eq!(camera.zoomed(1e-3).zoom, ZOOM_RANGE[0]);
        // Zoom scales distances from the centre.
        let ortho = OrbitCamera {
            projection: Projection::Orthographic,
            ..camera
        };
        let one = ortho.project([10.0, 0.0, 0.0], SIDE).unwrap();
        let two = ortho.zoomed(2.0).project([10.0, 0.0, 0.0], SIDE).unwrap();
        assert!(close(
            [two[0] - 200.0, two[1] - 200.0],
            [2.0 * (one[0] - 200.0), 2.0 * (one[1] - 200.0)]
        ));
    }
}
