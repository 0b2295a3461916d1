//! The paper's synthetic X-ray backgrounds (section II.A): a region around the heart, aorta or
//! superior vena cava is cropped from a chest radiograph, cut into a 4x4 grid of patches, and the
//! patches are placed at random into the grid of a new background on which the catheter is then
//! superimposed.
//!
//! The two styles differ in the patches' intensity, a rule made explicit here
//! ([`PatchRule`]): each patch keeps its own texture but is brought to a target mean
//! transmission. XRay-1 gives every patch the same high level (a bright, consistent background on
//! which the dark catheter is easy to see); XRay-2 makes a random half of the patches dark, so
//! the catheter crosses both dark and bright regions (hard).
//!
//! Backgrounds are transmission maps in `[0, 1]` (1 = nothing absorbs). A source radiograph is in
//! the radiograph convention (bright = dense), so a patch with radiograph values `g` and mean
//! `ḡ` becomes `T = level · exp(-k (g - ḡ))`: dense structures transmit less.

use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

use crate::simulator::carm::CArm;
use crate::simulator::phantom::{RadiographInBands, Thorax};
use crate::simulator::raster::{GreyImage, Rect};

/// The built-in phantom's field at the isocentre, millimetres: a whole adult chest.
pub const PHANTOM_FIELD_MM: f64 = 420.0;

/// The anatomical regions the generator crops around.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Anatomy {
    /// The cardiac silhouette.
    Heart,
    /// The aortic arch.
    Aorta,
    /// The superior vena cava.
    Svc,
}

impl Anatomy {
    /// All three regions.
    pub const ALL: [Anatomy; 3] = [Anatomy::Heart, Anatomy::Aorta, Anatomy::Svc];
}

/// How the patches' intensities are set (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PatchRule {
    /// Patches per side of the grid (the paper uses 4).
    pub grid: usize,
    /// Mean transmission of a bright patch.
    pub bright_level: f32,
    /// Mean transmission of a dark patch.
    pub dark_level: f32,
    /// Probability that a patch is dark (0 for XRay-1, 0.5 for XRay-2).
    pub dark_probability: f64,
    /// Texture contrast `k`: how strongly the radiograph's detail modulates the transmission.
    pub texture_contrast: f32,
    /// Side of the cropped region as a fraction of the source image's shorter side.
    pub region_size: [f64; 2],
    /// Random shift of the region's centre, as a fraction of the image size.
    pub region_jitter: f64,
    /// Whether each background's grid of patches starts at a random place (its mosaic rolled
    /// by up to a cell, wrapping round), so that the patches' edges fall anywhere; `false`, the
    /// paper's, puts them at fixed multiples of the cell (every 56 pixels at 224), where a
    /// network can learn to expect them (docs/log/2026-12-07-reading-each-view-twice.md).
    /// Files written before it existed read `false`, which is what they were, and `false` is
    /// not written, so that a seed's files stay byte for byte as they were.
    #[serde(default, skip_serializing_if = "core::ops::Not::not")]
    pub random_grid_offset: bool,
}

impl PatchRule {
    /// XRay-1: consistently bright patches.
    pub fn xray1() -> Self {
        Self {
            grid: 4,
            bright_level: 0.72,
            dark_level: 0.22,
            dark_probability: 0.0,
            texture_contrast: 2.0,
            region_size: [0.28, 0.40],
            region_jitter: 0.04,
            random_grid_offset: false,
        }
    }

    /// XRay-2: a random mix of dark and bright patches.
    pub fn xray2() -> Self {
        Self {
            dark_probability: 0.5,
            ..Self::xray1()
        }
    }
}

/// A radiograph to cut backgrounds from, with where its regions of interest are.
#[derive(Debug, Clone)]
pub struct BackgroundSource {
    /// What it is (a file name, or `phantom:<angles>`), recorded with each sample.
    pub name: String,
    /// The radiograph, bright where dense.
    pub image: GreyImage,
    /// Centre of each region, normalised image coordinates.
    pub regions: Vec<(Anatomy, [f64; 2])>,
}

impl BackgroundSource {
    /// A frontal (PA) chest radiograph from a file: regions at their usual places in such an
    /// image (the patient's left on the image's right).
    pub fn chest_radiograph(name: impl Into<String>, image: GreyImage) -> Self {
        Self {
            name: name.into(),
            image,
            regions: vec![
                (Anatomy::Heart, [0.57, 0.62]),
                (Anatomy::Aorta, [0.57, 0.36]),
                (Anatomy::Svc, [0.44, 0.40]),
            ],
        }
    }

    /// What the source is, in words for people: the file's name, or for the phantom
    /// "built-in thorax phantom" and its view (the recorded [`BackgroundSource::name`] stays
    /// terse).
    pub fn description(&self) -> String {
        match self.name.strip_prefix("phantom:") {
            Some(angles) => {
                let mut parts = angles.split('/');
                let (primary, secondary) =
                    (parts.next().unwrap_or("+0"), parts.next().unwrap_or("+0"));
                if primary.trim_start_matches(['+', '-']) == "0"
                    && secondary.trim_start_matches(['+', '-']) == "0"
                {
                    "Built-in thorax phantom (frontal view)".into()
                } else {
                    format!("Built-in thorax phantom (C-arm {primary}° / {secondary}°)")
                }
            }
            None => self.name.clone(),
        }
    }

    /// The built-in thorax phantom as seen from `view`'s direction ([`PHANTOM_FIELD_MM`] at
    /// the isocentre, `size_px` square), regions located by projecting the phantom's landmarks.
    pub fn phantom(view: &CArm, size_px: usize) -> Self {
        let mut render = Self::phantom_in_bands(view, size_px);
        while render.render_rows(size_px) {}
        Self::of_phantom(view, render)
    }

    /// [`Self::phantom`]'s radiograph, to render a band of rows at a time
    /// ([`RadiographInBands::render_rows`]) and make the source of with [`Self::of_phantom`]:
    /// the same source to the bit, for a caller that must answer in between (the page's
    /// thread).
    pub fn phantom_in_bands(view: &CArm, size_px: usize) -> RadiographInBands {
        Thorax::adult().radiograph_in_bands(view, PHANTOM_FIELD_MM, size_px)
    }

    /// The phantom source for `view` from its radiograph, rendered ([`Self::phantom_in_bands`]).
    pub fn of_phantom(view: &CArm, rendered: RadiographInBands) -> Self {
        let landmarks = rendered.landmarks();
        let (image, wide) = rendered.finish();
        let size_px = image.width;
        let at = |p| {
            let q = wide.project(p);
            [q.u / size_px as f64, q.v / size_px as f64]
        };
        Self {
            name: format!(
                "phantom:{:+.0}/{:+.0}",
                view.primary_deg, view.secondary_deg
            ),
            image,
            regions: vec![
                (Anatomy::Heart, at(landmarks.heart)),
                (Anatomy::Aorta, at(landmarks.aorta)),
                (Anatomy::Svc, at(landmarks.svc)),
            ],
        }
    }

    /// Where `anatomy` is in this radiograph (normalised), if it was located.
    pub fn region_centre(&self, anatomy: Anatomy) -> Option<[f64; 2]> {
        self.regions
            .iter()
            .find(|(a, _)| *a == anatomy)
            .map(|(_, c)| *c)
    }

    /// A square region (in pixels) of side `side` (fraction of the shorter image side) around a
    /// normalised centre, clamped into the image.
    pub fn square_region(&self, centre: [f64; 2], side: f64) -> Rect {
        let shorter = self.image.width.min(self.image.height) as f64;
        let size = [
            side * shorter / self.image.width as f64,
            side * shorter / self.image.height as f64,
        ];
        Rect::centred(centre, size).clamped()
    }
}

/// One background's random choices, saved with the sample so that it can be rebuilt.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PatchLayout {
    /// Which region the crop was centred on.
    pub anatomy: Option<Anatomy>,
    /// The cropped rectangle, normalised source coordinates.
    pub region: Rect,
    /// `permutation[cell]` is the source patch placed at grid cell `cell` (row-major).
    pub permutation: Vec<u8>,
    /// Whether the patch at each grid cell is dark.
    pub dark: Vec<bool>,
    /// Where the grid starts, as a fraction of a cell across and down, in `[0, 1)`
    /// ([`PatchRule::random_grid_offset`]); `[0, 0]` for the paper's fixed grid and for layouts
    /// saved before it existed (and not written, as [`PatchRule::random_grid_offset`]).
    #[serde(default, skip_serializing_if = "is_fixed_grid")]
    pub grid_offset: [f64; 2],
}

fn is_fixed_grid(offset: &[f64; 2]) -> bool {
    *offset == [0.0; 2]
}

/// A random start of the grid where `rule` asks for one ([`PatchRule::random_grid_offset`]),
/// drawn after the layout's other choices so that a fixed grid leaves the random stream as it
/// was.
fn grid_offset(rule: &PatchRule, rng: &mut impl Rng) -> [f64; 2] {
    if rule.random_grid_offset {
        [rng.random(), rng.random()]
    } else {
        [0.0; 2]
    }
}

impl PatchLayout {
    /// Random region (around one of `anatomies`), permutation and dark patches.
    pub fn random(
        source: &BackgroundSource,
        anatomies: &[Anatomy],
        rule: &PatchRule,
        rng: &mut impl Rng,
    ) -> Self {
        let located: Vec<_> = anatomies
            .iter()
            .filter_map(|a| source.region_centre(*a).map(|c| (*a, c)))
            .collect();
        let (anatomy, centre) = if located.is_empty() {
            (None, [0.5, 0.5])
        } else {
            let (a, c) = located[rng.random_range(0..located.len())];
            (Some(a), c)
        };
        let mut jitter = |c: f64| c + rule.region_jitter * (2.0 * rng.random::<f64>() - 1.0);
        let centre = [jitter(centre[0]), jitter(centre[1])];
        let side =
            rule.region_size[0] + (rule.region_size[1] - rule.region_size[0]) * rng.random::<f64>();
        let cells = rule.grid * rule.grid;
        let permutation = shuffled(cells, rng);
        let dark = (0..cells)
            .map(|_| rng.random::<f64>() < rule.dark_probability)
            .collect();
        Self {
            anatomy,
            region: source.square_region(centre, side),
            permutation,
            dark,
            grid_offset: grid_offset(rule, rng),
        }
    }

    /// The same region with a new random arrangement (the app's "shuffle" button).
    pub fn reshuffled(&self, rule: &PatchRule, rng: &mut impl Rng) -> Self {
        let cells = rule.grid * rule.grid;
        let permutation = shuffled(cells, rng);
        let dark = (0..cells)
            .map(|_| rng.random::<f64>() < rule.dark_probability)
            .collect();
        Self {
            anatomy: self.anatomy,
            region: self.region,
            permutation,
            dark,
            grid_offset: grid_offset(rule, rng),
        }
    }
}

/// A uniformly random permutation of `0..n` (Fisher-Yates).
fn shuffled(n: usize, rng: &mut impl Rng) -> Vec<u8> {
    let mut p: Vec<u8> = (0..n as u8).collect();
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        p.swap(i, j);
    }
    p
}

/// Builds the background transmission map `width` x `height` from `source` and `layout`.
pub fn compose(
    source: &BackgroundSource,
    layout: &PatchLayout,
    rule: &PatchRule,
    width: usize,
    height: usize,
) -> GreyImage {
    let grid = rule.grid;
    let crop = source.image.crop_resampled(layout.region, width, height);
    // Pixel bounds `(x0, x1, y0, y1)` of a cell (row-major in the grid).
    let bounds = |cell: usize| {
        let edge = |i: usize, size: usize| i * size / grid;
        let (r, c) = (cell / grid, cell % grid);
        (
            edge(c, width),
            edge(c + 1, width),
            edge(r, height),
            edge(r + 1, height),
        )
    };
    // Mean radiograph value of each source patch.
    let mut means = vec![0.0f32; grid * grid];
    for (cell, mean) in means.iter_mut().enumerate() {
        let (x0, x1, y0, y1) = bounds(cell);
        let mut sum = 0.0;
        for y in y0..y1 {
            sum += crop.data[y * width + x0..y * width + x1]
                .iter()
                .sum::<f32>();
        }
        *mean = sum / ((x1 - x0) * (y1 - y0)).max(1) as f32;
    }
    let mut out = GreyImage::filled(width, height, 0.0);
    for cell in 0..grid * grid {
        let source_cell = layout.permutation[cell] as usize;
        let level = if layout.dark[cell] {
            rule.dark_level
        } else {
            rule.bright_level
        };
        let (x0, x1, y0, y1) = bounds(cell);
        let (sx0, sx1, sy0, sy1) = bounds(source_cell);
        for y in y0..y1 {
            // Cells can differ by a pixel when the size is not a multiple of the grid.
            let sy = sy0 + (y - y0) * (sy1 - sy0) / (y1 - y0);
            for x in x0..x1 {
                let sx = sx0 + (x - x0) * (sx1 - sx0) / (x1 - x0);
                let g = crop.data[sy * width + sx];
                out.data[y * width + x] = (level
                    * (-rule.texture_contrast * (g - means[source_cell])).exp())
                .clamp(0.02, 1.0);
            }
        }
    }
    if layout.grid_offset == [0.0; 2] {
        return out;
    }
    // The mosaic rolled so that the grid starts at its offset, wrapping round.
    let roll = |fraction: f64, size: usize| {
        ((fraction.clamp(0.0, 1.0) * size as f64 / grid as f64) as usize).min(size - 1)
    };
    let (dx, dy) = (
        roll(layout.grid_offset[0], width),
        roll(layout.grid_offset[1], height),
    );
    let mut rolled = GreyImage::filled(width, height, 0.0);
    for y in 0..height {
        let from = &out.data[y * width..(y + 1) * width];
        let to = &mut rolled.data[((y + dy) % height) * width..][..width];
        to[dx..].copy_from_slice(&from[..width - dx]);
        to[..dx].copy_from_slice(&from[width - dx..]);
    }
    rolled
}

#[cfg(test)]
mod tests {
    use super::*;
    use hnet_units::ImageSize;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn ramp_source() -> BackgroundSource {
        // A radiograph whose value encodes the position, so patches can be recognised.
        let (w, h) = (64, 64);
        let data = (0..w * h)
            .map(|i| ((i % w) as f32 + (i / w) as f32 * 64.0) / (64.0 * 65.0))
            .collect();
        BackgroundSource::chest_radiograph(
            "ramp",
            GreyImage {
                width: w,
                height: h,
                data,
            },
        )
    }

    #[test]
    fn patches_are_a_permutation_of_the_crop() {
        let source = ramp_source();
        let rule = PatchRule {
            texture_contrast: 0.0,
            ..PatchRule::xray2()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let layout = PatchLayout::random(&source, &Anatomy::ALL, &rule, &mut rng);
        let mut sorted = layout.permutation.clone();
        sorted.sort();
        assert_eq!(sorted, (0..16).collect::<Vec<u8>>());
        // Without texture, every cell is exactly its level: dark cells dark, bright cells bright.
        let bg = compose(&source, &layout, &rule, 32, 32);
        for cell in 0..16 {
            let (r, c) = (cell / 4, cell % 4);
            let v = bg.data[(r * 8 + 3) * 32 + c * 8 + 3];
            let expected = if layout.dark[cell] {
                rule.dark_level
            } else {
                rule.bright_level
            };
            assert!((v - expected).abs() < 1e-6);
        }
    }

    #[test]
    fn xray1_is_bright_everywhere_and_xray2_mixes_dark_patches() {
        let source = ramp_source();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let one = PatchLayout::random(&source, &Anatomy::ALL, &PatchRule::xray1(), &mut rng);
        assert!(one.dark.iter().all(|d| !d));
        let darks: usize = (0..50)
            .map(|_| {
                PatchLayout::random(&source, &Anatomy::ALL, &PatchRule::xray2(), &mut rng)
                    .dark
                    .iter()
                    .filter(|d| **d)
                    .count()
            })
            .sum();
        // About half of 800 patches.
        assert!((320..480).contains(&darks), "{darks}");
    }

    #[test]
    fn a_moved_patch_keeps_its_texture() {
        let source = ramp_source();
        let rule = PatchRule::xray1();
        let layout = PatchLayout {
            anatomy: None,
            region: Rect([0.0, 0.0, 1.0, 1.0]),
            // Swap the first two cells, keep the rest.
            permutation: [1u8, 0].into_iter().chain(2..16).collect(),
            dark: vec![false; 16],
            grid_offset: [0.0; 2],
        };
        let bg = compose(&source, &layout, &rule, 64, 64);
        let identity = PatchLayout {
            permutation: (0..16).collect(),
            ..layout.clone()
        };
        let reference = compose(&source, &identity, &rule, 64, 64);
        for y in 0..16 {
            for x in 0..16 {
                assert_eq!(bg.data[y * 64 + x], reference.data[y * 64 + x + 16]);
                assert_eq!(bg.data[y * 64 + x + 16], reference.data[y * 64 + x]);
            }
        }
        assert_eq!(bg.data[40 * 64 + 40], reference.data[40 * 64 + 40]);
        // A grid started half a cell across and a quarter down is the same mosaic rolled by 8
        // and 4 pixels, wrapping round.
        let offset = PatchLayout {
            grid_offset: [0.5, 0.25],
            ..layout.clone()
        };
        let rolled = compose(&source, &offset, &rule, 64, 64);
        for (y, x) in [(0, 0), (3, 7), (10, 20), (63, 63), (40, 60)] {
            let (from_y, from_x) = ((y + 64 - 4) % 64, (x + 64 - 8) % 64);
            assert_eq!(rolled.data[y * 64 + x], bg.data[from_y * 64 + from_x]);
        }
        // The paper's fixed grid draws no offset, so a seed's layouts stay as they were.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let fixed = PatchLayout::random(&source, &Anatomy::ALL, &rule, &mut rng);
        assert_eq!(fixed.grid_offset, [0.0; 2]);
        let moving = PatchRule {
            random_grid_offset: true,
            ..rule
        };
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let offset = PatchLayout::random(&source, &Anatomy::ALL, &moving, &mut rng);
        assert_eq!(
            (&offset.permutation, &offset.dark),
            (&fixed.permutation, &fixed.dark)
        );
        assert!(offset.grid_offset.iter().all(|f| (0.0..1.0).contains(f)));
        assert_ne!(offset.grid_offset, [0.0; 2]);
    }

    #[test]
    fn the_phantom_locates_the_heart_near_the_image_centre() {
        let source =
            BackgroundSource::phantom(&CArm::cardiac(0.0, 0.0, ImageSize::square(224)), 96);
        let heart = source.region_centre(Anatomy::Heart).unwrap();
        assert!(
            (0.4..0.65).contains(&heart[0]) && (0.4..0.65).contains(&heart[1]),
            "{heart:?}"
        );
    }
}
