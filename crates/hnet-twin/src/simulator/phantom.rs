//! A procedural thorax phantom: torso, lungs, heart, great vessels, liver, spine, ribs and
//! clavicles as analytic shapes, projected with the C-arm geometry into a radiograph.
//!
//! It stands in for a chest X-ray file so that the app and the default dataset need no outside
//! image. Coordinates are the world frame of [`crate::simulator::carm`] (mm, `x` left, `y` anterior, `z`
//! cranial, isocentre in the heart). Each shape adds its attenuation relative to the tissue it
//! displaces (lungs are negative: air replaces soft tissue); values are effective linear
//! attenuation coefficients at about 60 keV, in 1/mm.

use hnet_units::ImageSize;
use serde::{Deserialize, Serialize};

use crate::simulator::carm::CArm;
use crate::simulator::raster::GreyImage;
use crate::vec3::{Mat3, Vec3};

#[derive(Debug, Clone, Copy)]
enum Shape {
    /// An ellipsoid: centre, rotation (columns: semi-axis directions), semi-axis lengths.
    Ellipsoid {
        centre: Vec3,
        axes: Mat3,
        semi: Vec3,
    },
    /// An elliptic cylinder along `z`, between two heights.
    CylinderZ {
        centre: Vec3,
        semi_x: f64,
        semi_y: f64,
        half_height: f64,
    },
    /// A cylinder of `radius` around the segment `a`-`b` (rib and vessel pieces).
    Rod { a: Vec3, b: Vec3, radius: f64 },
}

#[derive(Debug, Clone)]
struct Part {
    shape: Shape,
    attenuation_per_mm: f64,
    /// Shapes that take this part's place where they overlap it (the heart and mediastinum
    /// push the lungs aside).
    carved_by: Vec<Shape>,
}

impl Part {
    /// Length in mm of the ray inside this part (beyond the source, outside its carvings).
    fn chord(&self, origin: Vec3, dir: Vec3) -> f64 {
        let Some((t0, t1)) = self.shape.interval(origin, dir) else {
            return 0.0;
        };
        let (t0, t1) = (t0.max(0.0), t1.max(0.0));
        let mut length = t1 - t0;
        // Subtract the carved pieces, merged so that overlapping carvings count once.
        let mut cuts: Vec<(f64, f64)> = self
            .carved_by
            .iter()
            .filter_map(|c| c.interval(origin, dir).and_then(|i| intersect(i, (t0, t1))))
            .collect();
        cuts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut covered_until = f64::NEG_INFINITY;
        for (c0, c1) in cuts {
            let start = c0.max(covered_until);
            if c1 > start {
                length -= c1 - start;
                covered_until = c1;
            }
        }
        length.max(0.0)
    }
}

/// The `t` for which `origin + t·rate` lies in `[low, high]` (the whole line if `rate` is 0 and
/// `origin` is inside).
fn slab(origin: f64, rate: f64, low: f64, high: f64) -> Option<(f64, f64)> {
    if rate.abs() < 1e-12 {
        return (low..=high)
            .contains(&origin)
            .then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let (t0, t1) = ((low - origin) / rate, (high - origin) / rate);
    Some((t0.min(t1), t0.max(t1)))
}

fn intersect(a: (f64, f64), b: (f64, f64)) -> Option<(f64, f64)> {
    let (t0, t1) = (a.0.max(b.0), a.1.min(b.1));
    (t1 > t0).then_some((t0, t1))
}

/// Roots of `a t² + b t + c = 0` as an interval, if real.
fn quadratic_interval(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    if a <= 0.0 {
        return None;
    }
    let disc = b * b - 4.0 * a * c;
    (disc > 0.0).then(|| {
        let s = disc.sqrt();
        ((-b - s) / (2.0 * a), (-b + s) / (2.0 * a))
    })
}

impl Shape {
    /// The interval of `t` (a length in mm along the unit direction `dir`) for which
    /// `origin + t·dir` lies inside the shape, if any. Every shape is convex, so this is the
    /// whole intersection with the ray's line.
    fn interval(&self, origin: Vec3, dir: Vec3) -> Option<(f64, f64)> {
        match *self {
            Shape::Ellipsoid { centre, axes, semi } => {
                let local = axes.transpose();
                let o = local * (origin - centre);
                let d = local * dir;
                let o = Vec3::new(o[0] / semi[0], o[1] / semi[1], o[2] / semi[2]);
                let d = Vec3::new(d[0] / semi[0], d[1] / semi[1], d[2] / semi[2]);
                quadratic_interval(d.dot(d), 2.0 * o.dot(d), o.dot(o) - 1.0)
            }
            Shape::CylinderZ {
                centre,
                semi_x,
                semi_y,
                half_height,
            } => {
                let o = origin - centre;
                let (ox, oy, dx, dy) = (
                    o[0] / semi_x,
                    o[1] / semi_y,
                    dir[0] / semi_x,
                    dir[1] / semi_y,
                );
                let side = quadratic_interval(
                    dx * dx + dy * dy,
                    2.0 * (ox * dx + oy * dy),
                    ox * ox + oy * oy - 1.0,
                )?;
                intersect(side, slab(o[2], dir[2], -half_height, half_height)?)
            }
            Shape::Rod { a, b, radius } => {
                let axis = b - a;
                let length = axis.norm();
                let axis = axis / length;
                let w = origin - a;
                let d_perp = dir - axis * dir.dot(axis);
                let w_perp = w - axis * w.dot(axis);
                let side = quadratic_interval(
                    d_perp.dot(d_perp),
                    2.0 * w_perp.dot(d_perp),
                    w_perp.dot(w_perp) - radius * radius,
                )?;
                intersect(side, slab(w.dot(axis), dir.dot(axis), 0.0, length)?)
            }
        }
    }

    /// A sphere containing the shape: centre and radius.
    fn bounds(&self) -> (Vec3, f64) {
        match *self {
            Shape::Ellipsoid { centre, semi, .. } => (centre, semi.max_abs()),
            Shape::CylinderZ {
                centre,
                semi_x,
                semi_y,
                half_height,
            } => (
                centre,
                (semi_x.max(semi_y).powi(2) + half_height.powi(2)).sqrt(),
            ),
            Shape::Rod { a, b, radius } => ((a + b) * 0.5, (b - a).norm() / 2.0 + radius),
        }
    }
}

/// Landmarks the synthetic X-ray generator crops around (mm, world frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Landmarks {
    /// Centre of the cardiac silhouette.
    pub heart: Vec3,
    /// The aortic arch.
    pub aorta: Vec3,
    /// The superior vena cava.
    pub svc: Vec3,
}

/// The thorax phantom.
#[derive(Debug, Clone)]
pub struct Thorax {
    parts: Vec<Part>,
    /// Anatomical landmarks of this phantom.
    pub landmarks: Landmarks,
}

const SOFT_TISSUE: f64 = 0.0205;
const BONE: f64 = 0.030;

impl Default for Thorax {
    fn default() -> Self {
        Self::adult()
    }
}

impl Thorax {
    /// An average adult thorax, the heart around the isocentre.
    pub fn adult() -> Self {
        let ellipsoid = |centre: Vec3, semi: Vec3, tilt_about_y_deg: f64| Shape::Ellipsoid {
            centre,
            axes: Mat3::rotation(Vec3::Y, tilt_about_y_deg.to_radians()),
            semi,
        };
        let rod = |a: Vec3, b: Vec3, radius: f64| Shape::Rod { a, b, radius };
        let heart = ellipsoid(
            Vec3::new(18.0, 25.0, -18.0),
            Vec3::new(66.0, 50.0, 56.0),
            35.0,
        );
        let mediastinum = ellipsoid(Vec3::new(2.0, 10.0, 90.0), Vec3::new(30.0, 45.0, 75.0), 0.0);
        let arch = [
            Vec3::new(10.0, 25.0, 40.0),
            Vec3::new(6.0, 22.0, 85.0),
            Vec3::new(20.0, 5.0, 100.0),
            Vec3::new(34.0, -20.0, 90.0),
            Vec3::new(30.0, -42.0, 55.0),
            Vec3::new(24.0, -48.0, -40.0),
            Vec3::new(20.0, -50.0, -150.0),
        ];
        let vessels: Vec<Shape> = arch
            .windows(2)
            .map(|w| rod(w[0], w[1], 15.0))
            .chain([rod(
                Vec3::new(-28.0, 12.0, 35.0),
                Vec3::new(-26.0, 8.0, 115.0),
                12.0,
            )])
            .collect();
        let spine_column = rod(
            Vec3::new(0.0, -62.0, -260.0),
            Vec3::new(0.0, -62.0, 260.0),
            20.0,
        );
        // What pushes the lungs aside.
        let mut carving = vec![heart, mediastinum, spine_column];
        carving.extend(vessels.iter().copied());

        let mut parts = Vec::new();
        let mut add = |shape, attenuation_per_mm, carved_by: &[Shape]| {
            parts.push(Part {
                shape,
                attenuation_per_mm,
                carved_by: carved_by.to_vec(),
            })
        };
        // Torso: soft tissue from the neck to the abdomen.
        add(
            Shape::CylinderZ {
                centre: Vec3::new(0.0, -5.0, 0.0),
                semi_x: 160.0,
                semi_y: 110.0,
                half_height: 300.0,
            },
            SOFT_TISSUE,
            &[],
        );
        // Lungs: air (about 0.2 g/cm³ of tissue left) in place of soft tissue, except where the
        // heart, mediastinum, vessels and spine are.
        let lung = -0.8 * SOFT_TISSUE;
        add(
            ellipsoid(
                Vec3::new(-78.0, -8.0, 45.0),
                Vec3::new(66.0, 80.0, 128.0),
                6.0,
            ),
            lung,
            &carving,
        );
        add(
            ellipsoid(
                Vec3::new(80.0, -10.0, 38.0),
                Vec3::new(64.0, 76.0, 122.0),
                -6.0,
            ),
            lung,
            &carving,
        );
        // Blood and myocardium are a little denser than average soft tissue.
        add(heart, 0.06 * SOFT_TISSUE, &[]);
        for v in &vessels {
            add(*v, 0.06 * SOFT_TISSUE, &[]);
        }
        // Liver under the right hemidiaphragm.
        add(
            ellipsoid(
                Vec3::new(-55.0, 5.0, -150.0),
                Vec3::new(115.0, 85.0, 75.0),
                -10.0,
            ),
            0.05 * SOFT_TISSUE,
            &[],
        );
        // Spine: vertebral bodies every 27 mm with their posterior elements.
        for k in -9..=9 {
            let z = k as f64 * 27.0;
            add(
                ellipsoid(Vec3::new(0.0, -62.0, z), Vec3::new(21.0, 17.0, 11.5), 0.0),
                0.45 * BONE,
                &[],
            );
            add(
                rod(Vec3::new(-14.0, -82.0, z), Vec3::new(14.0, -82.0, z), 6.0),
                0.5 * BONE,
                &[],
            );
        }
        // Ribs: from the spine around the torso, descending towards the front.
        for k in 0..11 {
            let z0 = 185.0 - k as f64 * 24.0;
            for side in [-1.0, 1.0] {
                let point = |phi: f64| {
                    Vec3::new(
                        side * (22.0 + 118.0 * phi.sin()),
                        -72.0 - 20.0 * phi.cos() + 58.0 * (1.0 - phi.cos()),
                        z0 + 12.0 * phi - 26.0 * phi * phi,
                    )
                };
                let steps = 16;
                for i in 0..steps {
                    let (p0, p1) = (
                        0.1 + 2.6 * i as f64 / steps as f64,
                        0.1 + 2.6 * (i + 1) as f64 / steps as f64,
                    );
                    // Costal cartilage at the front is far less dense.
                    let density = if p0 > 2.1 { 0.3 } else { 0.8 };
                    add(rod(point(p0), point(p1), 5.5), density * BONE, &[]);
                }
            }
        }
        // Clavicles.
        for side in [-1.0, 1.0] {
            add(
                rod(
                    Vec3::new(side * 18.0, 45.0, 185.0),
                    Vec3::new(side * 145.0, 5.0, 210.0),
                    8.0,
                ),
                BONE,
                &[],
            );
        }
        Self {
            parts,
            landmarks: Landmarks {
                heart: Vec3::new(18.0, 25.0, -18.0),
                aorta: Vec3::new(20.0, 5.0, 95.0),
                svc: Vec3::new(-27.0, 10.0, 75.0),
            },
        }
    }

    /// The phantom's radiograph in `view`'s direction over a field of `field_mm` at the
    /// isocentre, `size_px` square, in the radiograph display convention (bright where the
    /// line integral of attenuation is large), normalised to `[0, 1]`.
    ///
    /// Returns the image and the wide view it was rendered with (to locate landmarks in it).
    pub fn radiograph(self, view: &CArm, field_mm: f64, size_px: usize) -> (GreyImage, CArm) {
        let mut render = self.radiograph_in_bands(view, field_mm, size_px);
        while render.render_rows(size_px) {}
        render.finish()
    }

    /// [`Self::radiograph`] rendered a band of rows at a time ([`RadiographInBands`]), for a
    /// caller that must answer in between (the page's thread); the same image to the bit.
    pub fn radiograph_in_bands(
        self,
        view: &CArm,
        field_mm: f64,
        size_px: usize,
    ) -> RadiographInBands {
        let wide = CArm {
            pixel_pitch_mm: field_mm * view.source_to_detector_mm
                / view.source_to_isocentre_mm
                / size_px as f64,
            image_size: ImageSize::square(size_px),
            ..*view
        };
        // Each part's bounding box in pixels, rows and columns inclusive.
        let focal = wide.focal_px();
        let boxes = self
            .parts
            .iter()
            .map(|part| {
                let (centre, radius) = part.shape.bounds();
                let p = wide.project(centre);
                let reach = radius * focal / (p.depth_mm - radius).max(1.0) + 1.0;
                let x0 = (p.u - reach).floor().max(0.0) as usize;
                let y0 = (p.v - reach).floor().max(0.0) as usize;
                let x1 = ((p.u + reach).ceil() as isize).min(size_px as isize - 1);
                let y1 = ((p.v + reach).ceil() as isize).min(size_px as isize - 1);
                (x1 >= 0 && y1 >= 0).then_some([x0, y0, x1 as usize, y1 as usize])
            })
            .collect();
        RadiographInBands {
            thorax: self,
            wide,
            boxes,
            line_integral: vec![0.0; size_px * size_px],
            next_row: 0,
        }
    }
}

/// A radiograph of the phantom being rendered a band of rows at a time
/// ([`Thorax::radiograph_in_bands`]): each pixel sums the same parts in the same order as one
/// pass would, so the bands make no difference to the image.
pub struct RadiographInBands {
    thorax: Thorax,
    /// The view rendered with, over the whole field.
    wide: CArm,
    /// Each part's pixel box `[x0, y0, x1, y1]` (inclusive), `None` when it is off the image.
    boxes: Vec<Option<[usize; 4]>>,
    /// Attenuation line integrals so far, row-major.
    line_integral: Vec<f64>,
    /// The first row not rendered yet.
    next_row: usize,
}

impl RadiographInBands {
    /// The landmarks of the phantom being rendered.
    pub fn landmarks(&self) -> Landmarks {
        self.thorax.landmarks
    }

    /// Renders the next `rows` rows (at least one); `true` while rows are left.
    pub fn render_rows(&mut self, rows: usize) -> bool {
        let size_px = self.wide.image_size.width;
        let (first, end) = (self.next_row, (self.next_row + rows.max(1)).min(size_px));
        let source = self.wide.source_mm();
        for (part, bounds) in self.thorax.parts.iter().zip(&self.boxes) {
            let Some([x0, y0, x1, y1]) = *bounds else {
                continue;
            };
            for y in y0.max(first)..=y1.min(end - 1) {
                for x in x0..=x1 {
                    let dir = self.wide.ray_direction(x as f64 + 0.5, y as f64 + 0.5);
                    self.line_integral[y * size_px + x] +=
                        part.attenuation_per_mm * part.chord(source, dir);
                }
            }
        }
        self.next_row = end;
        end < size_px
    }

    /// The radiograph, normalised between robust low and high percentiles of what was
    /// rendered, and the wide view it was rendered with.
    pub fn finish(self) -> (GreyImage, CArm) {
        let size_px = self.wide.image_size.width;
        let mut sorted = self.line_integral.clone();
        let n = sorted.len();
        // The two order statistics a full sort would give, in linear time.
        let high = *sorted
            .select_nth_unstable_by(n - 1 - n / 500, f64::total_cmp)
            .1;
        let low = *sorted.select_nth_unstable_by(n / 200, f64::total_cmp).1;
        let span = (high - low).max(1e-9);
        let data = self
            .line_integral
            .iter()
            .map(|v| (((v - low) / span) as f32).clamp(0.0, 1.0))
            .collect();
        (
            GreyImage {
                width: size_px,
                height: size_px,
                data,
            },
            self.wide,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chord(shape: &Shape, origin: Vec3, dir: Vec3) -> f64 {
        Part {
            shape: *shape,
            attenuation_per_mm: 1.0,
            carved_by: vec![],
        }
        .chord(origin, dir)
    }

    #[test]
    fn chords_of_simple_shapes_are_exact() {
        let sphere = Shape::Ellipsoid {
            centre: Vec3::ZERO,
            axes: Mat3::IDENTITY,
            semi: Vec3::new(10.0, 10.0, 10.0),
        };
        let origin = Vec3::new(0.0, -100.0, 0.0);
        assert!((chord(&sphere, origin, Vec3::Y) - 20.0).abs() < 1e-9);
        // Off-centre by 6: chord 2·sqrt(100 - 36) = 16.
        assert!((chord(&sphere, Vec3::new(6.0, -100.0, 0.0), Vec3::Y) - 16.0).abs() < 1e-9);
        let rod = Shape::Rod {
            a: Vec3::new(0.0, 0.0, -5.0),
            b: Vec3::new(0.0, 0.0, 5.0),
            radius: 2.0,
        };
        assert!((chord(&rod, origin, Vec3::Y) - 4.0).abs() < 1e-9);
        assert_eq!(chord(&rod, Vec3::new(0.0, -100.0, 9.0), Vec3::Y), 0.0);
        let torso = Shape::CylinderZ {
            centre: Vec3::ZERO,
            semi_x: 30.0,
            semi_y: 20.0,
            half_height: 50.0,
        };
        assert!((chord(&torso, origin, Vec3::Y) - 40.0).abs() < 1e-9);
        assert!((chord(&torso, Vec3::new(-100.0, 0.0, 0.0), Vec3::X) - 60.0).abs() < 1e-9);
        // A carving removes its overlap once, even when carvings overlap each other.
        let carved = Part {
            shape: torso,
            attenuation_per_mm: 1.0,
            carved_by: vec![sphere, sphere],
        };
        assert!((carved.chord(origin, Vec3::Y) - 20.0).abs() < 1e-9);
    }

    #[test]
    fn the_radiograph_shows_dark_lungs_and_a_bright_spine() {
        let view = CArm::cardiac(0.0, 0.0, ImageSize::square(224));
        let (image, wide) = Thorax::adult().radiograph(&view, 420.0, 128);
        let at = |p: Vec3| {
            let q = wide.project(p);
            image.data[q.v as usize * 128 + q.u as usize]
        };
        let lung = at(Vec3::new(-95.0, 0.0, 70.0));
        let spine_above_heart = at(Vec3::new(0.0, -62.0, 160.0));
        let heart = at(Vec3::new(30.0, 22.0, -30.0));
        assert!(
            lung < heart && heart < spine_above_heart,
            "{lung} {heart} {spine_above_heart}"
        );
        // Rendered a few rows at a time (the page's thread answering in between), the same
        // image to the bit.
        let mut bands = Thorax::adult().radiograph_in_bands(&view, 420.0, 128);
        let mut calls = 1;
        while bands.render_rows(7) {
            calls += 1;
        }
        assert_eq!(calls, 128usize.div_ceil(7));
        let (banded, banded_wide) = bands.finish();
        assert_eq!((banded, banded_wide), (image, wide));
    }
}
