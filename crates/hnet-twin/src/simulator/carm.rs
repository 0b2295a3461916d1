//! Perspective projection of a C-arm (or of a bench camera, which is the same pinhole model).
//!
//! World frame (millimetres), centred on the isocentre: `x` towards the patient's left, `y`
//! anterior, `z` cranial (towards the head). At both angles zero the X-ray source is posterior and
//! the beam travels along `+y` (a PA projection); the image's `u` axis (columns, to the right)
//! is the patient's left and its `v` axis (rows, downwards) points to the feet.
//!
//! The primary angle rotates the C-arm about the patient's long axis (`z`; positive = LAO), the
//! secondary angle tilts it about the left-right axis (`x`; positive = cranial). Pixel `(i, j)`
//! covers `[i, i+1) x [j, j+1)`; its centre is `(i + 0.5, j + 0.5)`.

use hnet_units::ImageSize;
use serde::{Deserialize, Serialize};

use crate::vec3::{Mat3, Vec3};

/// One view's geometry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CArm {
    /// Rotation about the patient's long axis in degrees (LAO positive, RAO negative).
    pub primary_deg: f64,
    /// Tilt about the patient's left-right axis in degrees (cranial positive, caudal negative).
    pub secondary_deg: f64,
    /// Distance from the focal spot to the isocentre, mm.
    pub source_to_isocentre_mm: f64,
    /// Distance from the focal spot to the detector, mm.
    pub source_to_detector_mm: f64,
    /// Detector pixel pitch, mm.
    pub pixel_pitch_mm: f64,
    /// Image size in pixels.
    #[serde(deserialize_with = "hnet_units::width_height_or_named")]
    pub image_size: ImageSize,
}

/// How far a C-arm's recorded settings (a DICOM header's angles and distances) may be from the
/// truth, for simulating a geometry the blind estimate reads wrong: each angle and each distance
/// is off by a uniform draw within the given bound, per view and per pair.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct HeaderError {
    /// Bound on the error of each angle (primary, secondary), degrees.
    pub angle_deg: f64,
    /// Bound on the error of each distance (source to isocentre, source to detector), mm.
    pub distance_mm: f64,
    /// Bound on how far plane B's isocentre is from plane A's along each world axis, mm, where
    /// the headers put both at one point (a biplane's two isocentres are calibrated to meet
    /// within a millimetre or two, and drift apart with wear).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub isocentre_mm: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl HeaderError {
    /// Whether it changes anything.
    pub fn is_none(&self) -> bool {
        self.angle_deg == 0.0 && self.distance_mm == 0.0 && self.isocentre_mm == 0.0
    }

    /// `camera` of plane B as the headers would give it when its true isocentre sits at
    /// `offset_mm` from plane A's (world frame): the camera of a C-arm centred at the origin
    /// reading a world shifted by `offset_mm`, `P' = P·T(offset)`.
    pub fn with_isocentre_offset(camera: CameraMatrix, offset_mm: [f64; 3]) -> CameraMatrix {
        let mut moved = camera;
        for row in &mut moved {
            row[3] += row[0] * offset_mm[0] + row[1] * offset_mm[1] + row[2] * offset_mm[2];
        }
        moved
    }

    /// `carm` as a header off by this error would record it; `unit` draws in `[0, 1)`.
    pub fn misread(&self, carm: &CArm, mut unit: impl FnMut() -> f64) -> CArm {
        let mut off = |bound: f64| bound * (2.0 * unit() - 1.0);
        let mut read = *carm;
        read.primary_deg += off(self.angle_deg);
        read.secondary_deg += off(self.angle_deg);
        read.source_to_isocentre_mm += off(self.distance_mm);
        read.source_to_detector_mm += off(self.distance_mm);
        read
    }
}

/// The 3x4 projection matrix `P = K [R | t]` mapping homogeneous world points (mm) to
/// homogeneous pixel coordinates.
pub type CameraMatrix = [[f64; 4]; 3];

/// A world point seen by a view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projected {
    /// Column coordinate in pixels.
    pub u: f64,
    /// Row coordinate in pixels.
    pub v: f64,
    /// Distance from the source along the beam axis, mm.
    pub depth_mm: f64,
}

impl CArm {
    /// A cardiac C-arm at the given angles, its images of `size` pixels: source 750 mm and
    /// detector 1200 mm from the focal spot, and a detector 150 mm wide (about 94 mm at the
    /// isocentre, the field of view of a zoomed cardiac run) with square pixels.
    pub fn cardiac(primary_deg: f64, secondary_deg: f64, size: ImageSize) -> Self {
        Self {
            primary_deg,
            secondary_deg,
            source_to_isocentre_mm: 750.0,
            source_to_detector_mm: 1200.0,
            pixel_pitch_mm: 150.0 / size.width as f64,
            image_size: size,
        }
    }

    /// A bench camera looking at the isocentre from 300 mm away, framing about 90 mm there
    /// across its images of `size` pixels.
    pub fn bench_camera(primary_deg: f64, secondary_deg: f64, size: ImageSize) -> Self {
        Self::bench_camera_at(primary_deg, secondary_deg, 300.0, size)
    }

    /// A bench camera (12 mm lens, 3.6 mm sensor width, square pixels) looking at the isocentre
    /// from `distance_mm`, framing `0.3 · distance_mm` there across its images of `size` pixels.
    pub fn bench_camera_at(
        primary_deg: f64,
        secondary_deg: f64,
        distance_mm: f64,
        size: ImageSize,
    ) -> Self {
        Self {
            primary_deg,
            secondary_deg,
            source_to_isocentre_mm: distance_mm,
            // A 12 mm focal length on a sensor 3.6 mm wide.
            source_to_detector_mm: 12.0,
            pixel_pitch_mm: 3.6 / size.width as f64,
            image_size: size,
        }
    }

    /// The same view rendered at another image size, keeping the detector's physical size.
    pub fn with_image_size(mut self, size: ImageSize) -> Self {
        self.pixel_pitch_mm *= self.image_size.width as f64 / size.width as f64;
        self.image_size = size;
        self
    }

    /// Rotation whose rows are the image axes `u`, `v` and the beam direction, in world axes.
    pub fn rotation(&self) -> Mat3 {
        // LAO turns the detector towards the patient's left (+x), cranial tilts it towards the
        // head (+z).
        let turn = Mat3::rotation(Vec3::Z, -self.primary_deg.to_radians())
            * Mat3::rotation(Vec3::X, self.secondary_deg.to_radians());
        // At zero angles: u = +x (patient left), v = -z (feet), beam = +y (anterior).
        let u = turn * Vec3::X;
        let v = turn * -Vec3::Z;
        let beam = turn * Vec3::Y;
        Mat3([u.0, v.0, beam.0])
    }

    /// The focal spot's position in mm.
    pub fn source_mm(&self) -> Vec3 {
        self.rotation().row(2) * -self.source_to_isocentre_mm
    }

    /// Focal length in pixels.
    pub fn focal_px(&self) -> f64 {
        self.source_to_detector_mm / self.pixel_pitch_mm
    }

    /// Projects a world point (mm).
    pub fn project(&self, point_mm: Vec3) -> Projected {
        let r = self.rotation();
        let rel = point_mm - self.source_mm();
        let depth = r.row(2).dot(rel);
        let f = self.focal_px();
        Projected {
            u: f * r.row(0).dot(rel) / depth + self.image_size.width as f64 / 2.0,
            v: f * r.row(1).dot(rel) / depth + self.image_size.height as f64 / 2.0,
            depth_mm: depth,
        }
    }

    /// Unit direction of the ray from the source through pixel coordinates `(u, v)`.
    pub fn ray_direction(&self, u: f64, v: f64) -> Vec3 {
        let r = self.rotation();
        let f = self.focal_px();
        let x = (u - self.image_size.width as f64 / 2.0) / f;
        let y = (v - self.image_size.height as f64 / 2.0) / f;
        (r.row(0) * x + r.row(1) * y + r.row(2)).normalized()
    }

    /// Millimetres at the isocentre per pixel.
    pub fn isocentre_mm_per_px(&self) -> f64 {
        self.pixel_pitch_mm * self.source_to_isocentre_mm / self.source_to_detector_mm
    }

    /// The projection matrix `K [R | t]` (pixel coordinates, world in mm), saved with each
    /// sample for 3D reconstruction.
    pub fn camera_matrix(&self) -> CameraMatrix {
        let r = self.rotation();
        let t = r * -self.source_mm();
        let f = self.focal_px();
        let (cx, cy) = (
            self.image_size.width as f64 / 2.0,
            self.image_size.height as f64 / 2.0,
        );
        let k = [[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]];
        let rt = [
            [r.0[0][0], r.0[0][1], r.0[0][2], t[0]],
            [r.0[1][0], r.0[1][1], r.0[1][2], t[1]],
            [r.0[2][0], r.0[2][1], r.0[2][2], t[2]],
        ];
        let mut p = [[0.0; 4]; 3];
        for (i, row) in p.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k_| k[i][k_] * rt[k_][j]).sum();
            }
        }
        p
    }
}

/// The C-arm angles a user can set on the page, degrees: view A's primary angle (LAO+, RAO-).
/// Off-bench training pairs draw their views from the same ranges, so that the shipped
/// model's masks are trained on every view the page can show.
pub const VIEW_A_PRIMARY_DEG: [f64; 2] = [-90.0, 90.0];
/// View B's primary angle range, degrees (a lateral plane swings further).
pub const VIEW_B_PRIMARY_DEG: [f64; 2] = [-90.0, 180.0];
/// Either view's secondary angle range (cranial+, caudal-), degrees.
pub const SECONDARY_DEG: [f64; 2] = [-40.0, 40.0];

/// The two views of a biplane system (or of the bench's two cameras).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Biplane {
    /// View A.
    pub a: CArm,
    /// View B.
    pub b: CArm,
}

impl Biplane {
    /// A biplane cardiac system: frontal (PA) and left lateral, 90° apart, both at `size`.
    pub fn cardiac(size: ImageSize) -> Self {
        Self {
            a: CArm::cardiac(0.0, 0.0, size),
            b: CArm::cardiac(90.0, 0.0, size),
        }
    }

    /// The paper's bench: two cameras 90° apart, both at `size`.
    pub fn bench(size: ImageSize) -> Self {
        Self {
            a: CArm::bench_camera(0.0, 0.0, size),
            b: CArm::bench_camera(90.0, 0.0, size),
        }
    }

    /// The paper's bench as its cameras saw it: two cameras 90° apart, 200 mm from the
    /// catheter, framing 60 mm there, so that the 50 mm flexible section fills most of the frame;
    /// both at `size`.
    pub fn paper_bench(size: ImageSize) -> Self {
        Self {
            a: CArm::bench_camera_at(0.0, 0.0, 200.0, size),
            b: CArm::bench_camera_at(90.0, 0.0, 200.0, size),
        }
    }

    /// Both views.
    pub fn views(&self) -> [&CArm; 2] {
        [&self.a, &self.b]
    }
}

/// Triangulates a world point from its pixel coordinates in two views (linear least squares, the
/// direct linear transform); used to check the saved camera matrices reconstruct the catheter.
pub fn triangulate(p_a: &CameraMatrix, uv_a: [f64; 2], p_b: &CameraMatrix, uv_b: [f64; 2]) -> Vec3 {
    // Rows u·P3 - P1 and v·P3 - P2 of both views; solve A [x y z] = -A[.., 3] in least squares.
    let rows = [
        (p_a, uv_a[0], 0),
        (p_a, uv_a[1], 1),
        (p_b, uv_b[0], 0),
        (p_b, uv_b[1], 1),
    ]
    .map(|(p, coord, i)| {
        let mut r = [0.0; 4];
        for (j, v) in r.iter_mut().enumerate() {
            *v = coord * p[2][j] - p[i][j];
        }
        r
    });
    let mut ata = [[0.0; 3]; 3];
    let mut atb = [0.0; 3];
    for r in &rows {
        for i in 0..3 {
            for j in 0..3 {
                ata[i][j] += r[i] * r[j];
            }
            atb[i] -= r[i] * r[3];
        }
    }
    // Cramer's rule on the 3x3 normal equations.
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&ata);
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = ata;
        for i in 0..3 {
            m[i][k] = atb[i];
        }
        *xk = det(&m) / d;
    }
    Vec3(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_isocentre_offset_reads_a_shifted_world() {
        let carm = CArm::cardiac(90.0, 0.0, ImageSize::square(128));
        let offset = [1.5, -2.0, 0.5];
        let moved = HeaderError::with_isocentre_offset(carm.camera_matrix(), offset);
        let p = Vec3::new(3.0, -4.0, 10.0);
        let shifted = carm.project(p + Vec3(offset));
        let h = |m: &CameraMatrix, q: Vec3| {
            let row = |r: &[f64; 4]| r[0] * q.0[0] + r[1] * q.0[1] + r[2] * q.0[2] + r[3];
            [row(&m[0]) / row(&m[2]), row(&m[1]) / row(&m[2])]
        };
        let [u, v] = h(&moved, p);
        assert!((u - shifted.u).abs() < 1e-9 && (v - shifted.v).abs() < 1e-9);
        assert!(
            !HeaderError {
                isocentre_mm: 2.0,
                ..HeaderError::default()
            }
            .is_none()
        );
    }

    #[test]
    fn the_isocentre_projects_to_the_image_centre() {
        for view in Biplane::cardiac(ImageSize::square(224)).views() {
            let p = view.project(Vec3::ZERO);
            assert!((p.u - 112.0).abs() < 1e-9 && (p.v - 112.0).abs() < 1e-9);
            assert!((p.depth_mm - 750.0).abs() < 1e-9);
        }
    }

    #[test]
    fn frontal_view_shows_the_patients_left_on_the_right_and_head_up() {
        let view = CArm::cardiac(0.0, 0.0, ImageSize::square(224));
        let left = view.project(Vec3::new(10.0, 0.0, 0.0));
        let head = view.project(Vec3::new(0.0, 0.0, 10.0));
        assert!(left.u > 112.0);
        assert!(head.v < 112.0);
        // Magnification 1200/750 = 1.6 at the isocentre.
        let mm_per_px = view.isocentre_mm_per_px();
        assert!((left.u - 112.0 - 10.0 / mm_per_px).abs() < 1e-9);
        // LAO 90 (left lateral): the detector is on the patient's left, the source on the right,
        // and left-right motion is seen only as depth.
        let lateral = CArm::cardiac(90.0, 0.0, ImageSize::square(224));
        assert!((lateral.rotation().row(2) - Vec3::X).max_abs() < 1e-12);
        assert!(lateral.source_mm().x() < 0.0);
        assert!((lateral.project(Vec3::new(10.0, 0.0, 0.0)).u - 112.0).abs() < 1e-9);
        // Cranial tilt moves the detector towards the head.
        let cranial = CArm::cardiac(0.0, 30.0, ImageSize::square(224));
        assert!(cranial.rotation().row(2).z() > 0.0);
    }

    #[test]
    fn camera_matrix_matches_projection_and_triangulates() {
        let biplane = Biplane {
            a: CArm::cardiac(-30.0, 20.0, ImageSize::square(224)),
            b: CArm::cardiac(60.0, -10.0, ImageSize::square(224)),
        };
        let point = Vec3::new(12.0, -7.0, 25.0);
        let mut uv = [[0.0; 2]; 2];
        for (i, view) in biplane.views().into_iter().enumerate() {
            let p = view.camera_matrix();
            let h: Vec<f64> = (0..3)
                .map(|r| (0..3).map(|c| p[r][c] * point[c]).sum::<f64>() + p[r][3])
                .collect();
            let projected = view.project(point);
            assert!((h[0] / h[2] - projected.u).abs() < 1e-9);
            assert!((h[1] / h[2] - projected.v).abs() < 1e-9);
            uv[i] = [projected.u, projected.v];
            // The ray through the projection passes through the point.
            let ray = view.ray_direction(projected.u, projected.v);
            let to_point = (point - view.source_mm()).normalized();
            assert!((ray - to_point).max_abs() < 1e-9);
        }
        let back = triangulate(
            &biplane.a.camera_matrix(),
            uv[0],
            &biplane.b.camera_matrix(),
            uv[1],
        );
        assert!((back - point).max_abs() < 1e-6, "{back:?}");
    }

    #[test]
    fn resizing_keeps_the_field_of_view() {
        let big = CArm::cardiac(0.0, 0.0, ImageSize::square(224));
        let small = big.with_image_size(ImageSize::square(112));
        let p = Vec3::new(20.0, 0.0, 15.0);
        let (a, b) = (big.project(p), small.project(p));
        assert!((a.u / 2.0 - b.u).abs() < 1e-9 && (a.v / 2.0 - b.v).abs() < 1e-9);
    }
}
