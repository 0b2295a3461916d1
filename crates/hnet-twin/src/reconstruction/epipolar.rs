//! The catheter in 3D from its centrelines in two views: epipolar matching and triangulation.
//!
//! Each view's 3x4 camera matrix `P` (world millimetres to pixels, as saved with every sample,
//! see [`crate::simulator::carm::CArm::camera_matrix`]) is checked (finite, rank 3, a finite centre) and the
//! two must have distinct centres. The fundamental matrix `F = [e_B]× P_B P_A⁺` then maps a point
//! of view A to its epipolar line in view B.
//!
//! **Matching.** For every point of A's centreline (proximal end to tip) its epipolar line is
//! intersected with B's centreline polyline; each crossing is a candidate match at a fractional
//! position along B, with the crossing angle between B's curve and the line. The chain of
//! candidates that keeps the order along both curves (a longest monotone chain, by dynamic
//! programming, crossings at a good angle counting double) picks one match per point, and
//! points of A whose epipolar line misses B's curve (the parts outside the other view) are left
//! out. When both tips are inside their images and lie on each other's epipolar lines within
//! [`ReconstructionSettings::max_tip_epipolar_px`], the two tips are matched too.
//!
//! **Conditioning.** A crossing at a shallow angle locates the match poorly (at 0° the whole
//! curve lies along the epipolar line and any point of it fits). Matches crossing at less than
//! [`ReconstructionSettings::min_crossing_deg`] are replaced by interpolation along B between
//! the well-conditioned matches around them; if fewer than
//! [`ReconstructionSettings::min_well_conditioned`] of the matched stretch is well-conditioned,
//! the pair is refused ([`ReconstructionError::AlongEpipolarLines`]) rather than reconstructed
//! wrongly.
//!
//! **Triangulation.** Each matched pair is triangulated by the direct linear transform
//! ([`crate::simulator::carm::triangulate`]); its residual is the root mean square reprojection error over
//! the two views, in pixels. The 3D curve is resampled at equal arc-length steps.
//!
//! nalgebra provides the small linear algebra (singular values for the rank check, the
//! pseudo-inverse); it is also what the rod fit's optimiser is built on.

use nalgebra::{Matrix3, Matrix3x4, Vector3, Vector4};
use serde::{Deserialize, Serialize};

use crate::reconstruction::centreline::Centreline;
use crate::simulator::carm::{CameraMatrix, triangulate};
use crate::simulator::rod::RodBase;
use crate::vec3::Vec3;

/// How two centrelines are matched and triangulated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionSettings {
    /// Largest arc-length step between the returned 3D points, mm.
    pub spacing_mm: f64,
    /// Epipolar lines crossing the other view's curve at less than this angle are
    /// ill-conditioned matches, degrees.
    pub min_crossing_deg: f64,
    /// Least fraction of the matched stretch whose matches must be well-conditioned.
    pub min_well_conditioned: f64,
    /// The tips are matched to each other when each lies within this distance of the other's
    /// epipolar line, pixels.
    pub max_tip_epipolar_px: f64,
    /// Fewest well-conditioned matches for a reconstruction.
    pub min_matches: usize,
    /// Smallest angle between the two views' rays at the reconstructed points (median over the
    /// curve; rays nearly opposite count as nearly parallel, so 0-90°), degrees: below it depth
    /// is too poorly determined to trust the shape (views a few degrees apart can match and
    /// triangulate consistently into a stretched, wrong catheter). A blind read raises it
    /// ([`crate::reconstruction::physics_force::BLIND_MIN_TRIANGULATION_DEG`]).
    pub min_triangulation_deg: f64,
}

impl Default for ReconstructionSettings {
    fn default() -> Self {
        Self {
            spacing_mm: 1.0,
            min_crossing_deg: 10.0,
            min_well_conditioned: 0.5,
            max_tip_epipolar_px: 3.0,
            min_matches: 5,
            min_triangulation_deg: 10.0,
        }
    }
}

/// The reconstructed catheter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reconstruction {
    /// Centreline points in mm (world frame), from where the catheter enters both images to the
    /// tip, equally spaced along the curve.
    pub points_mm: Vec<Vec3>,
    /// Arc length of each point from the first, mm.
    pub arc_mm: Vec<f64>,
    /// Reprojection error of each point (root mean square over the two views), pixels.
    pub residual_px: Vec<f64>,
    /// Mean of `residual_px`.
    pub mean_residual_px: f64,
    /// Fraction of the matched stretch whose epipolar crossings were well-conditioned.
    pub well_conditioned_fraction: f64,
    /// Whether the last point is the catheter's tip, seen inside both images.
    pub tip_seen: bool,
}

impl Reconstruction {
    /// The last point (the tip when [`Reconstruction::tip_seen`]).
    pub fn last_mm(&self) -> Vec3 {
        *self.points_mm.last().expect("a reconstruction has points")
    }
}

/// Why a pair cannot be reconstructed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReconstructionError {
    /// A camera matrix is unusable.
    #[error("view {view}: unusable camera matrix: {problem}")]
    InvalidCamera {
        /// The view's name.
        view: char,
        /// What is wrong.
        problem: String,
    },
    /// Both views are taken from the same point: there is no depth to triangulate.
    #[error(
        "the two views' centres are {distance_mm:.3e} mm apart: from one viewpoint there is no depth to triangulate"
    )]
    NoBaseline {
        /// Distance between the centres, mm.
        distance_mm: f64,
    },
    /// Too few points of the two centrelines lie on each other's epipolar lines.
    #[error(
        "only {matches} points of the two centrelines lie on each other's epipolar lines ({needed} needed): the views do not show the same stretch of catheter, or the camera matrices are not theirs"
    )]
    NoOverlap {
        /// Well-conditioned matches found.
        matches: usize,
        /// Least accepted.
        needed: usize,
    },
    /// The two views look at the catheter from nearly the same direction.
    #[error(
        "the two views see the catheter only {angle_deg:.1}° apart ({min_deg}° needed): depth cannot be triangulated reliably from so narrow an angle"
    )]
    NarrowAngle {
        /// Median angle between the views' rays at the catheter, degrees.
        angle_deg: f64,
        /// Least accepted, degrees.
        min_deg: f64,
    },
    /// The catheter lies along the epipolar lines over most of its length.
    #[error(
        "the catheter runs along the epipolar lines: only {:.0} % of it crosses them at {min_crossing_deg}° or more ({:.0} % needed), so the views cannot tell where its points are in depth",
        100.0 * fraction,
        100.0 * needed
    )]
    AlongEpipolarLines {
        /// Well-conditioned fraction of the matched stretch.
        fraction: f64,
        /// Least accepted fraction.
        needed: f64,
        /// The crossing angle that counts as well-conditioned, degrees.
        min_crossing_deg: f64,
    },
}

/// The epipolar geometry of two views.
#[derive(Debug, Clone, PartialEq)]
pub struct EpipolarGeometry {
    cameras: [CameraMatrix; 2],
    centres_mm: [Vec3; 2],
    /// `x_Bᵀ F x_A = 0`, Frobenius norm 1.
    fundamental: Matrix3<f64>,
}

fn matrix(p: &CameraMatrix) -> Matrix3x4<f64> {
    Matrix3x4::from_fn(|r, c| p[r][c])
}

/// Checks a camera matrix and returns its centre (mm).
fn camera_centre(p: &CameraMatrix, view: char) -> Result<Vec3, ReconstructionError> {
    let invalid = |problem: String| ReconstructionError::InvalidCamera { view, problem };
    if !p.iter().flatten().all(|v| v.is_finite()) {
        return Err(invalid("it has entries that are not finite numbers".into()));
    }
    let m = matrix(p);
    let singular = m.singular_values();
    let (largest, smallest) = (singular.max(), singular.min());
    if largest == 0.0 || smallest <= 1e-10 * largest {
        return Err(invalid(format!(
            "it has rank below 3 (singular values {:.3e}, {:.3e}, {:.3e})",
            singular[0], singular[1], singular[2]
        )));
    }
    // The centre is P's null vector: its cofactors along the columns.
    let minor = |skip: usize| {
        let cols: Vec<usize> = (0..4).filter(|&c| c != skip).collect();
        Matrix3::from_fn(|r, c| p[r][cols[c]]).determinant()
    };
    let c = Vector4::new(minor(0), -minor(1), minor(2), -minor(3));
    if c[3].abs() <= 1e-12 * c.norm() {
        return Err(invalid(
            "its centre is at infinity (an affine camera); a perspective view is needed".into(),
        ));
    }
    Ok(Vec3::new(c[0] / c[3], c[1] / c[3], c[2] / c[3]))
}

impl EpipolarGeometry {
    /// The geometry of views A and B, or why their camera matrices cannot be used.
    pub fn new(p_a: &CameraMatrix, p_b: &CameraMatrix) -> Result<Self, ReconstructionError> {
        let centre_a = camera_centre(p_a, 'A')?;
        let centre_b = camera_centre(p_b, 'B')?;
        let distance_mm = (centre_a - centre_b).norm();
        let scale = centre_a.norm().max(centre_b.norm()).max(1.0);
        if distance_mm <= 1e-6 * scale {
            return Err(ReconstructionError::NoBaseline { distance_mm });
        }
        let (a, b) = (matrix(p_a), matrix(p_b));
        let pseudo_inverse_a = a.transpose()
            * (a * a.transpose()).try_inverse().ok_or_else(|| {
                ReconstructionError::InvalidCamera {
                    view: 'A',
                    problem: "P Pᵀ is singular".into(),
                }
            })?;
        let epipole_b = b * Vector4::new(centre_a[0], centre_a[1], centre_a[2], 1.0);
        let fundamental = epipole_b.cross_matrix() * b * pseudo_inverse_a;
        let norm = fundamental.norm();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(ReconstructionError::NoBaseline { distance_mm });
        }
        Ok(Self {
            cameras: [*p_a, *p_b],
            centres_mm: [centre_a, centre_b],
            fundamental: fundamental / norm,
        })
    }

    /// The fundamental matrix `F` (`x_Bᵀ F x_A = 0`), row-major, Frobenius norm 1.
    pub fn fundamental(&self) -> [[f64; 3]; 3] {
        let f = &self.fundamental;
        [0, 1, 2].map(|r| [f[(r, 0)], f[(r, 1)], f[(r, 2)]])
    }

    /// The centre (X-ray source or camera) of view A (`0`) or B (`1`), mm.
    pub fn centre_mm(&self, view: usize) -> Vec3 {
        self.centres_mm[view]
    }

    /// The epipolar line in view B of point `uv_a` of view A: `[a, b, c]` with `a² + b² = 1`, so
    /// that `a·u + b·v + c` is the signed distance in pixels of `(u, v)` from the line.
    pub fn line_in_b(&self, uv_a: [f64; 2]) -> [f64; 3] {
        normalised_line(self.fundamental * Vector3::new(uv_a[0], uv_a[1], 1.0))
    }

    /// The epipolar line in view A of point `uv_b` of view B (as [`EpipolarGeometry::line_in_b`]).
    pub fn line_in_a(&self, uv_b: [f64; 2]) -> [f64; 3] {
        normalised_line(self.fundamental.transpose() * Vector3::new(uv_b[0], uv_b[1], 1.0))
    }

    /// Triangulates a matched pair: the world point (mm) and its reprojection error (root mean
    /// square over the two views, pixels).
    pub fn triangulate(&self, uv_a: [f64; 2], uv_b: [f64; 2]) -> (Vec3, f64) {
        let [p_a, p_b] = &self.cameras;
        let point = triangulate(p_a, uv_a, p_b, uv_b);
        let error = |p: &CameraMatrix, uv: [f64; 2]| {
            project(p, point).map_or(f64::INFINITY, |q| {
                (q[0] - uv[0]).powi(2) + (q[1] - uv[1]).powi(2)
            })
        };
        (point, ((error(p_a, uv_a) + error(p_b, uv_b)) / 2.0).sqrt())
    }
}

fn normalised_line(l: Vector3<f64>) -> [f64; 3] {
    let n = l[0].hypot(l[1]);
    if n > 0.0 {
        [l[0] / n, l[1] / n, l[2] / n]
    } else {
        [l[0], l[1], l[2]]
    }
}

/// Projects a world point (mm) with a camera matrix; `None` for a point in the camera's plane.
pub fn project(p: &CameraMatrix, point_mm: Vec3) -> Option<[f64; 2]> {
    let h =
        p.map(|row| row[0] * point_mm[0] + row[1] * point_mm[1] + row[2] * point_mm[2] + row[3]);
    (h[2].abs() > 1e-12).then(|| [h[0] / h[2], h[1] / h[2]])
}

/// Where a view sees the catheter's shaft come from: the projection of a point 50 mm behind the
/// rod's clamped base along its axis (`None` when that point is not in front of the view). As
/// [`crate::reconstruction::centreline::CentrelineSettings::proximal_hint_px`] it picks the proximal end of a
/// catheter whose mask touches the image border twice (its tip leaving the image too).
pub fn proximal_hint_px(camera: &CameraMatrix, base: &RodBase) -> Option<[f64; 2]> {
    let behind = base.position_mm - base.orientation.column(2) * 50.0;
    let depth = camera[2][0] * behind[0]
        + camera[2][1] * behind[1]
        + camera[2][2] * behind[2]
        + camera[2][3];
    (depth > 0.0).then(|| project(camera, behind)).flatten()
}

/// The part of line `[a, b, c]` (`a·u + b·v + c = 0`) inside the image `[0, width] x [0,
/// height]`, as its two end points; `None` when it misses the image. For drawing the epipolar
/// line of the pointer in the other view.
pub fn clip_line(line: [f64; 3], width: f64, height: f64) -> Option<[[f64; 2]; 2]> {
    let [a, b, c] = line;
    let mut points: Vec<[f64; 2]> = Vec::with_capacity(4);
    let mut add = |p: [f64; 2]| {
        let inside =
            (-1e-9..=width + 1e-9).contains(&p[0]) && (-1e-9..=height + 1e-9).contains(&p[1]);
        if inside
            && !points
                .iter()
                .any(|q| (q[0] - p[0]).hypot(q[1] - p[1]) < 1e-9)
        {
            points.push(p);
        }
    };
    if b.abs() > 1e-15 {
        add([0.0, -c / b]);
        add([width, -(c + a * width) / b]);
    }
    if a.abs() > 1e-15 {
        add([-c / a, 0.0]);
        add([-(c + b * height) / a, height]);
    }
    (points.len() >= 2).then(|| [points[0], points[1]])
}

/// One crossing of an epipolar line with the other view's curve.
#[derive(Debug, Clone, Copy)]
struct Crossing {
    /// Point index in view A.
    i: usize,
    /// Fractional point index along view B's curve.
    s: f64,
    /// Whether the crossing angle is at least the settings' minimum.
    good: bool,
}

/// The point at fractional index `s` of a polyline.
fn at_index(points: &[[f64; 2]], s: f64) -> [f64; 2] {
    let last = points.len() - 1;
    let j = (s.floor().max(0.0) as usize).min(last.saturating_sub(1));
    let t = (s - j as f64).clamp(0.0, 1.0);
    if last == 0 {
        return points[0];
    }
    let (p, q) = (points[j], points[j + 1]);
    [p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t]
}

/// Reconstructs the catheter from its centrelines in views A and B and the views' camera
/// matrices.
pub fn reconstruct(
    a: &Centreline,
    p_a: &CameraMatrix,
    b: &Centreline,
    p_b: &CameraMatrix,
    settings: &ReconstructionSettings,
) -> Result<Reconstruction, ReconstructionError> {
    let geometry = EpipolarGeometry::new(p_a, p_b)?;
    let (pa, pb) = (&a.points_px, &b.points_px);
    let (n, m) = (pa.len(), pb.len());
    let no_overlap = |matches| ReconstructionError::NoOverlap {
        matches,
        needed: settings.min_matches,
    };
    if n < 2 || m < 2 {
        return Err(no_overlap(0));
    }
    let min_sin = settings.min_crossing_deg.to_radians().sin();

    // Every crossing of every epipolar line with B's curve.
    let mut crossings = Vec::new();
    let mut distances = vec![0.0; m];
    for (i, &point) in pa.iter().enumerate() {
        let [la, lb, lc] = geometry.line_in_b(point);
        for (d, q) in distances.iter_mut().zip(pb) {
            *d = la * q[0] + lb * q[1] + lc;
        }
        for j in 0..m - 1 {
            let (d0, d1) = (distances[j], distances[j + 1]);
            if (d0 > 0.0) == (d1 > 0.0) {
                continue;
            }
            let t = if d0 == d1 { 0.0 } else { d0 / (d0 - d1) };
            let (q0, q1) = (pb[j], pb[j + 1]);
            let length = (q1[0] - q0[0]).hypot(q1[1] - q0[1]);
            let sin = if length > 0.0 {
                ((d0 - d1).abs() / length).min(1.0)
            } else {
                0.0
            };
            crossings.push(Crossing {
                i,
                s: j as f64 + t,
                good: sin >= min_sin,
            });
        }
    }

    // The heaviest chain in order along both curves.
    let weight = |c: &Crossing| if c.good { 2.0 } else { 1.0 };
    let k = crossings.len();
    let mut best = vec![0.0f64; k];
    let mut previous = vec![None; k];
    for x in 0..k {
        best[x] = weight(&crossings[x]);
        for y in 0..x {
            if crossings[y].i < crossings[x].i
                && crossings[y].s <= crossings[x].s + 1e-9
                && best[y] + weight(&crossings[x]) > best[x]
            {
                best[x] = best[y] + weight(&crossings[x]);
                previous[x] = Some(y);
            }
        }
    }
    let mut chain = Vec::new();
    let mut at = (0..k).max_by(|&x, &y| best[x].total_cmp(&best[y]));
    while let Some(x) = at {
        chain.push(crossings[x]);
        at = previous[x];
    }
    chain.reverse();

    // The well-conditioned matches, and the tips.
    let mut anchors: Vec<(usize, f64)> = chain
        .iter()
        .filter(|c| c.good)
        .map(|c| (c.i, c.s))
        .collect();
    let good_matches = anchors.len();
    let tip_seen = !a.tip_at_border && !b.tip_at_border && {
        let [la, lb, lc] = geometry.line_in_b(a.tip_px());
        let [ka, kb, kc] = geometry.line_in_a(b.tip_px());
        let (tb, ta) = (b.tip_px(), a.tip_px());
        (la * tb[0] + lb * tb[1] + lc).abs() <= settings.max_tip_epipolar_px
            && (ka * ta[0] + kb * ta[1] + kc).abs() <= settings.max_tip_epipolar_px
    };
    if tip_seen {
        let tip = (n - 1, (m - 1) as f64);
        anchors.retain(|&(i, s)| i < tip.0 && s <= tip.1);
        anchors.push(tip);
    }
    if good_matches < settings.min_matches {
        return Err(if chain.len() >= settings.min_matches {
            ReconstructionError::AlongEpipolarLines {
                fraction: good_matches as f64 / chain.len() as f64,
                needed: settings.min_well_conditioned,
                min_crossing_deg: settings.min_crossing_deg,
            }
        } else {
            no_overlap(good_matches)
        });
    }
    let (first, last) = (anchors[0].0, anchors[anchors.len() - 1].0);
    let fraction = good_matches.min(last - first + 1) as f64 / (last - first + 1) as f64;
    if fraction < settings.min_well_conditioned {
        return Err(ReconstructionError::AlongEpipolarLines {
            fraction,
            needed: settings.min_well_conditioned,
            min_crossing_deg: settings.min_crossing_deg,
        });
    }

    // Positions along B for every point of A between the first and last anchors, triangulated.
    let mut points = Vec::with_capacity(last - first + 1);
    let mut residuals = Vec::with_capacity(last - first + 1);
    let mut next = 0;
    for (i, &point_a) in pa.iter().enumerate().take(last + 1).skip(first) {
        while anchors[next].0 < i {
            next += 1;
        }
        let s = if anchors[next].0 == i {
            anchors[next].1
        } else {
            let (i0, s0) = anchors[next - 1];
            let (i1, s1) = anchors[next];
            s0 + (s1 - s0) * (i - i0) as f64 / (i1 - i0) as f64
        };
        let (point, residual) = geometry.triangulate(point_a, at_index(pb, s));
        points.push(point);
        residuals.push(residual);
    }

    // The angle between the two rays at each point: too narrow, and depth is guesswork. Rays
    // nearly opposite (sources on either side of the catheter) are as ill-conditioned as rays
    // nearly parallel, so the angle is folded to at most 90°.
    let mut angles: Vec<f64> = points
        .iter()
        .map(|p| {
            let (ra, rb) = (*p - geometry.centre_mm(0), *p - geometry.centre_mm(1));
            let cos = ra.dot(rb) / (ra.norm() * rb.norm()).max(1e-12);
            let angle = cos.clamp(-1.0, 1.0).acos().to_degrees();
            angle.min(180.0 - angle)
        })
        .collect();
    angles.sort_by(f64::total_cmp);
    let angle_deg = angles.get(angles.len() / 2).copied().unwrap_or(0.0);
    // NaN angles (degenerate rays) fail too.
    if angle_deg.is_nan() || angle_deg < settings.min_triangulation_deg {
        return Err(ReconstructionError::NarrowAngle {
            angle_deg,
            min_deg: settings.min_triangulation_deg,
        });
    }

    // Equal arc-length steps.
    let mut arc = vec![0.0];
    for w in points.windows(2) {
        arc.push(arc[arc.len() - 1] + (w[1] - w[0]).norm());
    }
    let length = arc[arc.len() - 1];
    let segments = (length / settings.spacing_mm.max(1e-6)).ceil().max(1.0) as usize;
    let mut points_mm = Vec::with_capacity(segments + 1);
    let mut residual_px = Vec::with_capacity(segments + 1);
    let mut arc_mm = Vec::with_capacity(segments + 1);
    for k in 0..=segments {
        let s = length * k as f64 / segments as f64;
        let j = arc
            .partition_point(|&x| x < s)
            .clamp(1, arc.len().max(2) - 1);
        let (point, residual) = if points.len() == 1 {
            (points[0], residuals[0])
        } else {
            let span = arc[j] - arc[j - 1];
            let t = if span > 0.0 {
                ((s - arc[j - 1]) / span).clamp(0.0, 1.0)
            } else {
                1.0
            };
            (
                points[j - 1] + (points[j] - points[j - 1]) * t,
                residuals[j - 1] + (residuals[j] - residuals[j - 1]) * t,
            )
        };
        points_mm.push(point);
        residual_px.push(residual);
        arc_mm.push(s);
    }
    let mean_residual_px = residual_px.iter().sum::<f64>() / residual_px.len() as f64;
    Ok(Reconstruction {
        points_mm,
        arc_mm,
        residual_px,
        mean_residual_px,
        well_conditioned_fraction: fraction,
        tip_seen: tip_seen && last == n - 1,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::reconstruction::centreline::{
        CentrelineError, CentrelineSettings, Mask, extract_centreline,
    };
    use crate::simulator::carm::{Biplane, CArm};
    use crate::simulator::render::PROXIMAL_SHAFT_MM;
    use crate::simulator::rod::RodShape;
    use crate::simulator::scene::{Backgrounds, Modality, StereoSample, TwinConfig, generate};
    use hnet_units::ImageSize;

    /// Bench XRay-2 sample `index` at `size` px, and its twin settings.
    pub(crate) fn bench_sample(size: usize, seed: u64, index: u64) -> (TwinConfig, StereoSample) {
        let config = TwinConfig::new(Modality::Xray2, ImageSize::square(size));
        let backgrounds = Backgrounds::phantom(&config.views);
        let sample = generate(&config, &backgrounds, seed, index).unwrap();
        (config, sample)
    }

    /// The centreline of view `view` (0 for A, 1 for B) from its `size`-pixel mask.
    pub(crate) fn mask_centreline(
        mask: &[u8],
        size: usize,
        view: usize,
    ) -> Result<Centreline, CentrelineError> {
        extract_centreline(
            &Mask::coverage8(size, size, mask),
            ["A", "B"][view],
            &CentrelineSettings::default(),
        )
    }

    /// The sample's catheter reconstructed from its true masks at `size` pixels.
    pub(crate) fn reconstruct_true_masks(sample: &StereoSample, size: usize) -> Reconstruction {
        let [a, b] = [0, 1].map(|i| mask_centreline(&sample.views[i].mask, size, i).unwrap());
        reconstruct(
            &a,
            &sample.views[0].camera,
            &b,
            &sample.views[1].camera,
            &ReconstructionSettings::default(),
        )
        .unwrap()
    }

    /// Distance from `p` to the true centreline (the flexible section and its proximal shaft).
    pub(crate) fn distance_to_truth(shape: &RodShape, p: Vec3) -> f64 {
        crate::reconstruction::rod_fit::distances_to_rod(shape, PROXIMAL_SHAFT_MM, &[p])[0]
    }

    /// How far `r` is from the true catheter `shape`: the mean distance of its points and the
    /// distance of its last point from the true tip, mm.
    pub(crate) fn errors_to_truth(r: &Reconstruction, shape: &RodShape) -> (f64, f64) {
        let distances = crate::reconstruction::rod_fit::distances_to_rod(
            shape,
            PROXIMAL_SHAFT_MM,
            &r.points_mm,
        );
        let mean = distances.iter().sum::<f64>() / distances.len() as f64;
        (mean, (r.last_mm() - shape.tip_mm()).norm())
    }

    #[test]
    fn a_twin_pair_is_reconstructed_from_its_true_masks() {
        let size = 128;
        for index in 0..3 {
            let (_, sample) = bench_sample(size, 5, index);
            let r = reconstruct_true_masks(&sample, size);
            let (mean, tip) = errors_to_truth(&r, &sample.shape);
            assert!(r.tip_seen);
            assert!(mean < 0.3, "sample {index}: mean error {mean} mm");
            assert!(tip < 1.0, "sample {index}: tip error {tip} mm");
            assert!(r.mean_residual_px < 0.3, "{}", r.mean_residual_px);
            // It covers the flexible section from below its base (the shaft enters the images
            // lower down) to the tip.
            let base = sample.shape.points_mm[0];
            assert!(r.points_mm[0].z() < base.z(), "{:?}", r.points_mm[0]);
            let steps: Vec<f64> = r.arc_mm.windows(2).map(|w| w[1] - w[0]).collect();
            assert!(steps.iter().all(|&s| s <= 1.0 + 1e-9 && s > 0.8));
        }
    }

    #[test]
    fn epipolar_lines_pass_through_the_matching_point() {
        let views = Biplane {
            a: CArm::cardiac(-30.0, 20.0, ImageSize::square(200)),
            b: CArm::cardiac(60.0, -10.0, ImageSize::square(160)),
        };
        let (pa, pb) = (views.a.camera_matrix(), views.b.camera_matrix());
        let geometry = EpipolarGeometry::new(&pa, &pb).unwrap();
        assert!((geometry.centre_mm(0) - views.a.source_mm()).norm() < 1e-6);
        assert!((geometry.centre_mm(1) - views.b.source_mm()).norm() < 1e-6);
        for point in [Vec3::new(12.0, -7.0, 25.0), Vec3::new(-30.0, 10.0, -5.0)] {
            let (a, b) = (project(&pa, point).unwrap(), project(&pb, point).unwrap());
            let l = geometry.line_in_b(a);
            assert!((l[0] * b[0] + l[1] * b[1] + l[2]).abs() < 1e-6);
            let k = geometry.line_in_a(b);
            assert!((k[0] * a[0] + k[1] * a[1] + k[2]).abs() < 1e-6);
            let (back, residual) = geometry.triangulate(a, b);
            assert!((back - point).norm() < 1e-6 && residual < 1e-6);
            // The visible part of the line ends on the image's border.
            let [e0, e1] = clip_line(l, 160.0, 160.0).unwrap();
            for e in [e0, e1] {
                assert!((l[0] * e[0] + l[1] * e[1] + l[2]).abs() < 1e-9);
                let on_edge = [e[0], 160.0 - e[0], e[1], 160.0 - e[1]]
                    .iter()
                    .any(|d| d.abs() < 1e-9);
                assert!(on_edge, "{e:?}");
            }
        }
        assert_eq!(clip_line([1.0, 0.0, 10.0], 100.0, 100.0), None);
    }

    #[test]
    fn the_shaft_comes_from_below_the_base() {
        let params = crate::simulator::scene::SceneSampling::bench()
            .sample(&mut crate::simulator::scene::sample_rng(1, 0));
        let (_, base) = params.rod(&crate::simulator::rod::RodConfig::default());
        for view in Biplane::cardiac(ImageSize::square(64)).views() {
            let hint = proximal_hint_px(&view.camera_matrix(), &base).unwrap();
            // The base points cranially, so the shaft comes from the image's bottom edge.
            assert!(hint[1] > 64.0 && (0.0..64.0).contains(&hint[0]), "{hint:?}");
        }
    }

    /// A centreline through the projections of `points` (no border contact).
    fn centreline_of(view: &CArm, points: &[Vec3]) -> Centreline {
        let points_px: Vec<[f64; 2]> = points
            .iter()
            .map(|p| {
                let q = view.project(*p);
                [q.u, q.v]
            })
            .collect();
        let arc_px = crate::reconstruction::centreline::arc_lengths(&points_px);
        Centreline {
            points_px,
            arc_px,
            width_px: 4.0,
            proximal_at_border: false,
            tip_at_border: false,
            set_aside_px: Vec::new(),
        }
    }

    #[test]
    fn degenerate_cameras_are_refused() {
        let views = Biplane::cardiac(ImageSize::square(128));
        let good = views.a.camera_matrix();
        let line = centreline_of(
            &views.a,
            &(0..20)
                .map(|k| Vec3::new(0.0, 0.0, k as f64))
                .collect::<Vec<_>>(),
        );
        let settings = ReconstructionSettings::default();
        let mut nan = good;
        nan[1][2] = f64::NAN;
        let err = reconstruct(&line, &good, &line, &nan, &settings).unwrap_err();
        assert!(
            matches!(err, ReconstructionError::InvalidCamera { view: 'B', .. }),
            "{err}"
        );
        assert!(err.to_string().contains("not finite"), "{err}");
        let mut flat = good;
        flat[2] = flat[1];
        let err = reconstruct(&line, &flat, &line, &good, &settings).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("view A: unusable camera matrix: it has rank below 3"),
            "{err}"
        );
        let mut affine = good;
        affine[2] = [0.0, 0.0, 0.0, 1.0];
        let err = reconstruct(&line, &affine, &line, &good, &settings).unwrap_err();
        assert!(err.to_string().contains("at infinity"), "{err}");
        // The same source, another detector (twice the pixels): no baseline.
        let mut zoomed = good;
        for row in &mut zoomed[..2] {
            row.iter_mut().for_each(|v| *v *= 2.0);
        }
        let err = reconstruct(&line, &good, &line, &zoomed, &settings).unwrap_err();
        assert!(
            matches!(err, ReconstructionError::NoBaseline { .. }),
            "{err}"
        );
        // Two views 3° apart see a curved catheter consistently, but give it no reliable depth;
        // nor do two views 177° apart, from either side of the catheter.
        let curve: Vec<Vec3> = (0..40)
            .map(|k| {
                let t = k as f64 / 39.0;
                Vec3::new(20.0 * t * t, 10.0 * t, 40.0 * t - 20.0)
            })
            .collect();
        for primary_deg in [3.0, 177.0] {
            let b = crate::simulator::carm::CArm::cardiac(primary_deg, 0.0, ImageSize::square(128));
            let err = reconstruct(
                &centreline_of(&views.a, &curve),
                &good,
                &centreline_of(&b, &curve),
                &b.camera_matrix(),
                &settings,
            )
            .unwrap_err();
            assert!(
                matches!(err, ReconstructionError::NarrowAngle { angle_deg, .. } if angle_deg < 10.0),
                "{primary_deg}°: {err}"
            );
        }
    }

    #[test]
    fn a_catheter_along_the_epipolar_lines_is_refused() {
        // Both sources lie in the plane z = 0, so that plane is an epipolar plane: a catheter
        // lying (nearly) in it runs along the epipolar lines in both views.
        let views = Biplane::cardiac(ImageSize::square(128));
        let points: Vec<Vec3> = (0..=40)
            .map(|k| {
                let t = k as f64 - 20.0;
                Vec3::new(t, -t, 0.03 * t)
            })
            .collect();
        // The catheter through `in_a` as view A sees it and through `in_b` as view B does.
        let seen = |in_a: &[Vec3], in_b: &[Vec3]| {
            reconstruct(
                &centreline_of(&views.a, in_a),
                &views.a.camera_matrix(),
                &centreline_of(&views.b, in_b),
                &views.b.camera_matrix(),
                &ReconstructionSettings::default(),
            )
        };
        let err = seen(&points, &points).unwrap_err();
        assert!(
            matches!(err, ReconstructionError::AlongEpipolarLines { fraction, .. } if fraction < 0.5),
            "{err}"
        );
        assert!(err.to_string().contains("runs along the epipolar lines"));
        // Turned to cross them, it is reconstructed.
        let crossing: Vec<Vec3> = points
            .iter()
            .map(|p| Vec3::new(p.x(), p.y(), p.x()))
            .collect();
        let r = seen(&crossing, &crossing).unwrap();
        assert!((r.points_mm[0] - crossing[0]).norm() < 1e-6);
        assert!((r.last_mm() - crossing[40]).norm() < 1e-6);
        // Views of different stretches do not match.
        let high: Vec<Vec3> = crossing
            .iter()
            .map(|p| *p + Vec3::new(0.0, 0.0, 60.0))
            .collect();
        let err = seen(&crossing, &high).unwrap_err();
        assert!(
            matches!(err, ReconstructionError::NoOverlap { .. }),
            "{err}"
        );
    }
}
