//! Drawing the catheter into one view: its exact anti-aliased mask, its X-ray attenuation
//! (Beer-Lambert) and its look under the bench's lights.
//!
//! The catheter is a tube of constant diameter around the solved centreline. Each centreline
//! segment projects to a 2D capsule whose radius follows the perspective scale at its ends; a
//! pixel's coverage is `clamp(0.5 - d, 0, 1)` where `d` is the signed distance in pixels from the
//! pixel centre to the tube's outline (a one-pixel box filter of the exact outline).

use hnet_units::ImageSize;
use rand::{Rng, RngExt};

use crate::simulator::carm::CArm;
use crate::simulator::catheter::CatheterDesign;
use crate::simulator::noise::Noise;
use crate::simulator::raster::{GreyImage, RgbImage};
use crate::simulator::rod::RodShape;

/// The catheter as seen by one view.
#[derive(Debug, Clone, PartialEq)]
pub struct TubeRaster {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Fraction of each pixel covered by the catheter: the exact anti-aliased mask.
    pub coverage: Vec<f32>,
    /// X-ray attenuation `μ·chord` (dimensionless) along the ray through each pixel centre.
    pub attenuation: Vec<f32>,
    /// For pixels the catheter touches: signed position across the nearest visible tube,
    /// -1 at one silhouette edge, 0 on the axis, 1 at the other; NaN elsewhere.
    pub across: Vec<f32>,
    /// Whether the visible surface at the pixel is an electrode.
    pub electrode: Vec<bool>,
    depth: Vec<f32>,
}

impl TubeRaster {
    /// No catheter in a `width` x `height` view (a catheter-free image through the same
    /// renderer).
    pub fn empty(width: usize, height: usize) -> Self {
        let n = width * height;
        Self {
            width,
            height,
            coverage: vec![0.0; n],
            attenuation: vec![0.0; n],
            across: vec![f32::NAN; n],
            electrode: vec![false; n],
            depth: vec![f32::INFINITY; n],
        }
    }

    /// Whether the catheter's outline reaches the pixel at `index`.
    pub fn is_touched(&self, index: usize) -> bool {
        !self.across[index].is_nan()
    }
}

/// Length of the stiff proximal shaft drawn behind the flexible section's base, mm: enough to
/// leave any field of view, as the real catheter does.
pub const PROXIMAL_SHAFT_MM: f64 = 250.0;

/// Projects and rasterises the catheter of `shape` (diameter `diameter_mm`) in `view`: the
/// flexible section and, straight behind its clamped base, the proximal shaft.
pub fn rasterize_catheter(
    shape: &RodShape,
    diameter_mm: f64,
    design: &CatheterDesign,
    view: &CArm,
) -> TubeRaster {
    let ImageSize { width, height } = view.image_size;
    let mut raster = TubeRaster::empty(width, height);
    let radius_mm = diameter_mm / 2.0;
    let focal = view.focal_px();
    let source = view.source_mm();
    let length = *shape.arc_mm.last().unwrap_or(&0.0);
    let mut points = Vec::with_capacity(shape.points_mm.len() + 1);
    let mut arcs = Vec::with_capacity(shape.points_mm.len() + 1);
    if let (Some(base), Some(axis)) = (shape.points_mm.first(), shape.tangents.first()) {
        points.push(*base - *axis * PROXIMAL_SHAFT_MM);
        arcs.push(-PROXIMAL_SHAFT_MM);
    }
    points.extend_from_slice(&shape.points_mm);
    arcs.extend_from_slice(&shape.arc_mm);
    let projected: Vec<_> = points.iter().map(|p| view.project(*p)).collect();

    for i in 0..projected.len().saturating_sub(1) {
        let (a, b) = (projected[i], projected[i + 1]);
        // Skip what lies behind the source.
        if a.depth_mm <= 1.0 || b.depth_mm <= 1.0 {
            continue;
        }
        let (ra, rb) = (
            radius_mm * focal / a.depth_mm,
            radius_mm * focal / b.depth_mm,
        );
        let (pa, pb) = (points[i], points[i + 1]);
        let tangent = (pb - pa).normalized();
        let ray = (((pa + pb) * 0.5) - source).normalized();
        // Rays nearly along the tube see a longer path; cap the growth where the segment is
        // seen end-on (its projection there is a disc and the cap stands in for the bend).
        let obliquity = tangent.cross(ray).norm().max(0.25);
        let (sa, sb) = (arcs[i], arcs[i + 1]);
        let reach = ra.max(rb) + 1.0;
        let x_min = (a.u.min(b.u) - reach).floor().max(0.0) as usize;
        let x_max = ((a.u.max(b.u) + reach).ceil() as isize).min(width as isize - 1);
        let y_min = (a.v.min(b.v) - reach).floor().max(0.0) as usize;
        let y_max = ((a.v.max(b.v) + reach).ceil() as isize).min(height as isize - 1);
        if x_max < 0 || y_max < 0 {
            continue;
        }
        let (du, dv) = (b.u - a.u, b.v - a.v);
        let len2 = du * du + dv * dv;
        for y in y_min..=y_max as usize {
            for x in x_min..=x_max as usize {
                let (cu, cv) = (x as f64 + 0.5, y as f64 + 0.5);
                let t = if len2 > 0.0 {
                    (((cu - a.u) * du + (cv - a.v) * dv) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let (qu, qv) = (a.u + t * du, a.v + t * dv);
                let dist = ((cu - qu).powi(2) + (cv - qv).powi(2)).sqrt();
                let rho = ra + t * (rb - ra);
                let coverage = (0.5 - (dist - rho)).clamp(0.0, 1.0) as f32;
                if coverage <= 0.0 {
                    continue;
                }
                let index = y * width + x;
                let px = &mut raster.coverage[index];
                *px = px.max(coverage);
                let from_tip = length - (sa + t * (sb - sa));
                if dist < rho {
                    let chord = 2.0 * radius_mm * (1.0 - (dist / rho).powi(2)).sqrt() / obliquity;
                    let att = (design.attenuation_per_mm(from_tip) * chord) as f32;
                    let px = &mut raster.attenuation[index];
                    *px = px.max(att);
                }
                let depth = (a.depth_mm + t * (b.depth_mm - a.depth_mm)) as f32;
                if depth < raster.depth[index] {
                    raster.depth[index] = depth;
                    let side = (du * (cv - a.v) - dv * (cu - a.u)).signum();
                    raster.across[index] = (side * (dist / rho).min(1.0)) as f32;
                    raster.electrode[index] = design.is_electrode(from_tip);
                }
            }
        }
    }
    raster
}

/// Detector physics of the X-ray renderer. Fields left out of a JSON file take their defaults
/// (`hnet simulate --detector FILE`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct XRayDetector {
    /// Photons per pixel reaching the detector where nothing attenuates; quantum noise has a
    /// relative standard deviation of `1/sqrt(photons · transmission)`.
    pub photons_per_pixel: f64,
    /// Standard deviation of the detector's Gaussian blur, pixels.
    pub blur_px: f64,
    /// Share of the detected signal that is scatter and veiling glare, 0-1: spread over the
    /// frame as a broad blur (σ an eighth of the image's width), it lowers the catheter's
    /// contrast without moving it. 0 (none) by default.
    #[serde(skip_serializing_if = "is_zero")]
    pub scatter_fraction: f64,
    /// Exponent of the display's grey curve, `grey = T^γ`: below 1 lifts the dark end (a
    /// brighter, flatter picture), above 1 deepens it. 1 (linear) by default.
    #[serde(skip_serializing_if = "is_one")]
    pub display_gamma: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

impl Default for XRayDetector {
    fn default() -> Self {
        Self {
            photons_per_pixel: 2500.0,
            blur_px: 0.6,
            scatter_fraction: 0.0,
            display_gamma: 1.0,
        }
    }
}

impl XRayDetector {
    /// Why these settings cannot make an image, naming the field.
    pub fn check(&self) -> Result<(), String> {
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("`{name}` = {v} is not a finite number"))
            }
        };
        finite("photons_per_pixel", self.photons_per_pixel)?;
        finite("blur_px", self.blur_px)?;
        finite("scatter_fraction", self.scatter_fraction)?;
        finite("display_gamma", self.display_gamma)?;
        if self.photons_per_pixel <= 0.0 {
            return Err(format!(
                "`photons_per_pixel` = {} must be above 0",
                self.photons_per_pixel
            ));
        }
        if !(0.0..=10.0).contains(&self.blur_px) {
            return Err(format!(
                "`blur_px` = {} is outside 0-10 pixels",
                self.blur_px
            ));
        }
        if !(0.0..1.0).contains(&self.scatter_fraction) {
            return Err(format!(
                "`scatter_fraction` = {} is outside [0, 1)",
                self.scatter_fraction
            ));
        }
        if !(0.1..=10.0).contains(&self.display_gamma) {
            return Err(format!(
                "`display_gamma` = {} is outside 0.1-10",
                self.display_gamma
            ));
        }
        Ok(())
    }
}

/// Ranges of X-ray detectors to draw from, one per pair (a training stream's imaging
/// randomisation): each setting uniform within its `[low, high]`, the dose on a log scale.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetectorRanges {
    /// Photons per pixel, drawn log-uniformly.
    pub photons_per_pixel: [f64; 2],
    /// Blur σ, pixels.
    pub blur_px: [f64; 2],
    /// Scatter and veiling glare, share of the signal.
    pub scatter_fraction: [f64; 2],
    /// The display curve's exponent.
    pub display_gamma: [f64; 2],
}

impl DetectorRanges {
    /// Why these ranges cannot be drawn from, naming the field: reversed or not finite, or
    /// an end no detector may have ([`XRayDetector::check`]).
    pub fn check(&self) -> Result<(), String> {
        for (name, [lo, hi]) in [
            ("photons_per_pixel", self.photons_per_pixel),
            ("blur_px", self.blur_px),
            ("scatter_fraction", self.scatter_fraction),
            ("display_gamma", self.display_gamma),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(format!(
                    "`{name}` must be a range [low, high] of finite numbers, low ≤ high"
                ));
            }
        }
        for end in [0, 1] {
            XRayDetector {
                photons_per_pixel: self.photons_per_pixel[end],
                blur_px: self.blur_px[end],
                scatter_fraction: self.scatter_fraction[end],
                display_gamma: self.display_gamma[end],
            }
            .check()?;
        }
        Ok(())
    }

    /// One detector drawn from the ranges.
    pub fn draw(&self, rng: &mut impl Rng) -> XRayDetector {
        let mut uniform = |[lo, hi]: [f64; 2]| lo + (hi - lo) * rng.random::<f64>();
        let [lo, hi] = self.photons_per_pixel;
        XRayDetector {
            photons_per_pixel: uniform([lo.ln(), hi.ln()]).exp(),
            blur_px: uniform(self.blur_px),
            scatter_fraction: uniform(self.scatter_fraction),
            display_gamma: uniform(self.display_gamma),
        }
    }
}

/// An X-ray frame in the fluoroscopy display convention: the grey value is the relative
/// transmitted intensity, so the catheter shows dark on the background's transmission map.
///
/// `T = T_background · exp(-μL)` (Beer-Lambert), then Poisson quantum noise (Gaussian
/// approximation), then the detector blur; then, when the detector has them, scatter and veiling
/// glare (`(1 - s)·T + s·blur(T)`) and the display's grey curve (`T^γ`).
pub fn render_xray(
    background_transmission: &GreyImage,
    tube: &TubeRaster,
    detector: &XRayDetector,
    rng: &mut impl Rng,
) -> GreyImage {
    let inverse_photons = 1.0 / detector.photons_per_pixel as f32;
    let mut noise = Noise::from_rng(rng);
    let data = background_transmission
        .data
        .iter()
        .zip(&tube.attenuation)
        .map(|(&t, &att)| {
            let t = if att > 0.0 { t * (-att).exp() } else { t };
            (t + (t.max(0.0) * inverse_photons).sqrt() * noise.normal()).clamp(0.0, 1.0)
        })
        .collect();
    let mut frame = GreyImage {
        width: tube.width,
        height: tube.height,
        data,
    }
    .blurred(detector.blur_px);
    let scatter = detector.scatter_fraction as f32;
    if scatter > 0.0 {
        let veil = frame.blurred(tube.width.max(tube.height) as f64 / 8.0);
        for (t, v) in frame.data.iter_mut().zip(&veil.data) {
            *t = (1.0 - scatter) * *t + scatter * v;
        }
    }
    if detector.display_gamma != 1.0 {
        let gamma = detector.display_gamma as f32;
        frame
            .data
            .iter_mut()
            .for_each(|t| *t = t.clamp(0.0, 1.0).powf(gamma));
    }
    frame
}

/// The bench's background: a matte board under a soft light with a faint 10 mm grid, as the
/// camera's optics see it (noise is added by [`render_bench`]).
pub fn bench_background(view: &CArm, rng: &mut impl Rng) -> RgbImage {
    let ImageSize { width, height } = view.image_size;
    // Board tint and light placement vary a little from shot to shot.
    let tint = [
        0.80 + 0.04 * rng.random::<f32>(),
        0.78 + 0.04 * rng.random::<f32>(),
        0.72 + 0.05 * rng.random::<f32>(),
    ];
    let light = [rng.random::<f32>(), rng.random::<f32>()];
    let grid_px = 10.0 / view.isocentre_mm_per_px();
    let phase = [rng.random::<f64>() * grid_px, rng.random::<f64>() * grid_px];
    // Light falloff, vignetting and the grid are separable: tabulate them per column and row.
    let line = |c: usize, phase: f64| {
        let m = (c as f64 + 0.5 + phase).rem_euclid(grid_px);
        (1.0 - m.min(grid_px - m) as f32).clamp(0.0, 1.0)
    };
    let axis = |n: usize, light: f32, phase: f64| -> Vec<(f32, f32, f32)> {
        (0..n)
            .map(|i| {
                let f = (i as f32 + 0.5) / n as f32;
                ((f - light).powi(2), (f - 0.5).powi(2), line(i, phase))
            })
            .collect()
    };
    let (columns, rows) = (
        axis(width, light[0], phase[0]),
        axis(height, light[1], phase[1]),
    );
    let mut data = Vec::with_capacity(width * height * 3);
    for &(light_y, vignette_y, grid_y) in &rows {
        for &(light_x, vignette_x, grid_x) in &columns {
            let lit = 0.82 + 0.18 * (1.0 - (light_x + light_y));
            let vignette = 1.0 - 0.48 * (vignette_x + vignette_y);
            let grid = grid_x.max(grid_y);
            let shade = lit * vignette;
            data.push(tint[0] * shade * (1.0 - 0.10 * grid));
            data.push(tint[1] * shade * (1.0 - 0.07 * grid));
            data.push(tint[2] * shade * (1.0 - 0.10 * grid));
        }
    }
    RgbImage {
        width,
        height,
        data,
    }
}

/// A bench-camera photograph: the catheter shaded as a glossy tube (Lambertian plus a specular
/// highlight) over `background`, the optics' slight blur, then the sensor's noise.
pub fn render_bench(
    background: &RgbImage,
    tube: &TubeRaster,
    design: &CatheterDesign,
    rng: &mut impl Rng,
) -> RgbImage {
    const BLUR_PX: f64 = 0.45;
    let mut photo = background.clone();
    // Light from the upper left of the tube's cross-section.
    let light_across = -0.45f32;
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, &coverage) in tube.coverage.iter().enumerate() {
        if coverage <= 0.0 || !tube.is_touched(i) {
            continue;
        }
        let (x, y) = (i % tube.width, i / tube.width);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        let across = tube.across[i];
        let facing = (1.0 - across * across).max(0.0).sqrt();
        let (colour, gloss, sharpness) = if tube.electrode[i] {
            (design.electrode_colour, 0.55, 12)
        } else {
            (design.shaft_colour, 0.30, 20)
        };
        let diffuse = 0.30 + 0.70 * facing * (1.0 - 0.35 * (across - light_across).abs());
        let highlight = gloss
            * (1.0 - (across - light_across).abs())
                .max(0.0)
                .powi(sharpness);
        for (px, channel) in photo.data[i * 3..i * 3 + 3].iter_mut().zip(colour) {
            let tube_value = channel * diffuse + highlight;
            *px = *px * (1.0 - coverage) + tube_value * coverage;
        }
    }
    // The board is smooth, so the blur only changes the image around the catheter.
    if x0 <= x1 {
        let margin = 3;
        photo.blur_region(
            [x0.saturating_sub(margin), y0.saturating_sub(margin)],
            [
                (x1 + margin + 1).min(photo.width),
                (y1 + margin + 1).min(photo.height),
            ],
            BLUR_PX,
        );
    }
    // Sensor noise, after the optics: mostly luminance, a little per channel.
    let mut noise = Noise::from_rng(rng);
    for px in photo.data.chunks_exact_mut(3) {
        let luminance = 0.012 * noise.normal();
        for v in px {
            *v += luminance;
        }
    }
    photo
}

/// How far a photograph's pixel must differ from the empty bench's, in any channel (linear RGB,
/// 0-1), to be catheter: eight times the sensor's noise, below the darkest shading of the shaft
/// and of the electrodes against the board.
pub const CUTOUT_LEVEL: f32 = 0.10;

/// The catheter of a bench photograph, thresholded against the empty bench `board` (a reference
/// frame, as a bench records before the catheter goes in): 255 where a channel differs by more
/// than [`CUTOUT_LEVEL`], else 0.
pub fn bench_cutout(photo: &RgbImage, board: &RgbImage) -> Vec<u8> {
    photo
        .data
        .chunks_exact(3)
        .zip(board.data.chunks_exact(3))
        .map(|(p, b)| {
            let differs = p.iter().zip(b).any(|(p, b)| (p - b).abs() > CUTOUT_LEVEL);
            if differs { 255 } else { 0 }
        })
        .collect()
}

/// The paper's synthetic X-ray frame: `transmission` (the patch shuffle) with the `cutout`
/// pixels of `photo` pasted over it as grey (BT.601 luma), nothing else done to the frame.
pub fn paste_cutout(transmission: &GreyImage, photo: &RgbImage, cutout: &[u8]) -> GreyImage {
    let data = transmission
        .data
        .iter()
        .zip(photo.data.chunks_exact(3))
        .zip(cutout)
        .map(|((&t, p), &cut)| {
            if cut == 0 {
                t
            } else {
                0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
            }
        })
        .collect();
    GreyImage {
        width: transmission.width,
        height: transmission.height,
        data,
    }
}

/// Centre of mass of a mask in pixel coordinates, or `None` if it is empty.
pub fn mask_centroid(coverage: &[f32], width: usize) -> Option<[f64; 2]> {
    let (mut sx, mut sy, mut total) = (0.0, 0.0, 0.0);
    for (i, &c) in coverage.iter().enumerate() {
        let c = f64::from(c);
        sx += c * ((i % width) as f64 + 0.5);
        sy += c * ((i / width) as f64 + 0.5);
        total += c;
    }
    (total > 0.0).then(|| [sx / total, sy / total])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::rod::{RodBase, RodConfig, solve};
    use crate::vec3::Vec3;
    use rand::SeedableRng;

    fn straight_catheter() -> RodShape {
        // The flexible 50 mm from z = -25 mm to +25 mm through the isocentre, the proximal shaft
        // below.
        let base = RodBase {
            position_mm: Vec3::new(0.0, 0.0, -25.0),
            ..RodBase::default()
        };
        solve(&RodConfig::default(), &base, Vec3::ZERO).unwrap()
    }

    /// The tests' catheter diameter, mm.
    const DIAMETER_MM: f64 = 2.33;

    /// The frontal view at `size` pixels and the straight catheter rasterised in it.
    fn straight_tube(size: usize) -> (CArm, TubeRaster) {
        let view = CArm::cardiac(0.0, 0.0, ImageSize::square(size));
        let design = CatheterDesign::default();
        let tube = rasterize_catheter(&straight_catheter(), DIAMETER_MM, &design, &view);
        (view, tube)
    }

    #[test]
    fn the_mask_covers_the_projected_tube_and_nothing_else() {
        let (view, tube) = straight_tube(224);
        // The tube's projected width at the isocentre, in pixels.
        let width_px = DIAMETER_MM / view.isocentre_mm_per_px();
        // Area: from the tip (with its round cap) down to the image's bottom edge.
        let tip_v = view.project(Vec3::new(0.0, 0.0, 25.0)).v;
        let length_px = 224.0 - tip_v;
        let rect = length_px * width_px;
        let r = width_px / 2.0;
        let cap = std::f64::consts::PI * r * r / 2.0;
        let area: f64 = tube.coverage.iter().map(|&c| f64::from(c)).sum();
        assert!(
            (area - rect - cap).abs() / (rect + cap) < 0.03,
            "{area} vs {}",
            rect + cap
        );
        // It is vertical and centred in the frontal view; its centroid is that of the shaft
        // and the tip's half-disc.
        let c = mask_centroid(&tube.coverage, 224).unwrap();
        assert!((c[0] - 112.0).abs() < 0.05, "{c:?}");
        let cap_centroid = tip_v - 4.0 * r / (3.0 * std::f64::consts::PI);
        let expected_v = (rect * (tip_v + 224.0) / 2.0 + cap * cap_centroid) / (rect + cap);
        assert!((c[1] - expected_v).abs() < 0.3, "{c:?} vs {expected_v}");
        // Pixels far from the axis are untouched.
        assert_eq!(tube.coverage[112 * 224 + 112 + 10], 0.0);
        assert_eq!(tube.coverage[112 * 224 + 112], 1.0);
    }

    #[test]
    fn electrodes_attenuate_far_more_than_the_shaft() {
        let (view, tube) = straight_tube(224);
        let row_of = |z: f64| view.project(Vec3::new(0.0, 0.0, z)).v as usize;
        // Tip electrode near z = +24 mm, shaft at z = 0.
        let tip = tube.attenuation[row_of(23.5) * 224 + 112];
        let shaft = tube.attenuation[row_of(0.0) * 224 + 112];
        assert!(
            tip > 2.0 && shaft < 0.3 && shaft > 0.1,
            "tip {tip}, shaft {shaft}"
        );
        assert!(tube.electrode[row_of(23.5) * 224 + 112]);
    }

    #[test]
    fn xray_frames_show_the_catheter_dark() {
        let (view, tube) = straight_tube(64);
        let background = GreyImage::filled(64, 64, 0.7);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let frame = render_xray(&background, &tube, &XRayDetector::default(), &mut rng);
        let row = view.project(Vec3::new(0.0, 0.0, 23.5)).v as usize;
        assert!(frame.data[row * 64 + 32] < 0.3);
        assert!((frame.data[5 * 64 + 5] - 0.7).abs() < 0.1);
    }
}
