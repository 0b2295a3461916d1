//! A complete stereo sample of a scene: the twin's settings ([`TwinConfig`]), both views
//! rendered with their masks, and [`generate`], which draws a scene, solves its catheter and
//! renders it. Re-exported by [`crate::simulator::scene`].

use hnet_units::ImageSize;
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{Modality, SceneParams, SceneSampling};
use crate::simulator::carm::{Biplane, CArm, CameraMatrix};
use crate::simulator::catheter::CatheterDesign;
use crate::simulator::phantom::RadiographInBands;
use crate::simulator::raster::{GreyImage, RgbImage};
use crate::simulator::render::{self, TubeRaster, XRayDetector};
use crate::simulator::rod::{self, RodConfig, RodError, RodShape};
use crate::simulator::sensor_plate::{self, ContactError};
use crate::simulator::synthetic_xray::{self, Anatomy, BackgroundSource, PatchLayout, PatchRule};
use crate::vec3::Vec3;

/// How a simulated set's label masks are made (`mask` in its `dataset.json`). Not to be confused
/// with [`crate::reconstruction::MaskOrigin`], which masks a reconstruction read.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind", content = "level")]
pub enum MaskRecipe {
    /// Exact anti-aliased coverage from the geometry.
    Geometry,
    /// The paper's way: threshold the rendered image (catheter darker than the level, 0-255).
    Threshold(u8),
    /// Threshold at Otsu's level of each image.
    Otsu,
    /// The bench photograph's catheter, thresholded against the empty bench
    /// ([`render::bench_cutout`]): the paper's masks, and on the paper's bench the very pixels
    /// its X-ray recipe pastes onto the patches. The exact geometry's where there is no bench
    /// photograph (C-arm X-ray sets).
    Cutout,
}

/// How an X-ray set's frames are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum XRayRecipe {
    /// The catheter's attenuation over the patch background, through the detector's physics
    /// (noise, blur, scatter, display curve): the clinical C-arm sets.
    #[default]
    Detector,
    /// The paper's recipe: the bench photograph's catheter, thresholded, pasted (as grey) onto
    /// the shuffled patches, with nothing else done to the frame.
    Pasted,
}

/// Everything that defines the twin's output, saved with a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TwinConfig {
    /// The look of the images.
    pub modality: Modality,
    /// The images' size, pixels. Files written before [`ImageSize`] existed hold a square's
    /// bare side.
    #[serde(deserialize_with = "hnet_units::side_or_named")]
    pub image_size: ImageSize,
    /// Random scene parameters.
    pub scene: SceneSampling,
    /// The rod's fixed properties (length, stiffness and pre-curvature come from the scene).
    pub rod: RodConfig,
    /// The catheter's design.
    pub catheter: CatheterDesign,
    /// The two views.
    pub views: Biplane,
    /// X-ray detector physics (X-ray modalities).
    pub detector: XRayDetector,
    /// Background patch rule (X-ray modalities).
    pub patches: PatchRule,
    /// Regions to crop backgrounds around (X-ray modalities).
    pub anatomies: Vec<Anatomy>,
    /// How masks are made.
    pub mask: MaskRecipe,
    /// How X-ray frames are made (X-ray modalities).
    #[serde(default)]
    pub xray_recipe: XRayRecipe,
}

impl TwinConfig {
    /// The defaults for a modality at an image size: bench cameras for `rgb`, a biplane cardiac
    /// C-arm for the X-ray modalities.
    pub fn new(modality: Modality, image_size: ImageSize) -> Self {
        Self {
            modality,
            image_size,
            scene: SceneSampling::default(),
            rod: RodConfig::default(),
            catheter: CatheterDesign::default(),
            views: if modality.is_xray() {
                Biplane::cardiac(image_size)
            } else {
                Biplane::bench(image_size)
            },
            detector: XRayDetector::default(),
            patches: if modality == Modality::Xray2 {
                PatchRule::xray2()
            } else {
                PatchRule::xray1()
            },
            anatomies: Anatomy::ALL.to_vec(),
            mask: MaskRecipe::Geometry,
            xray_recipe: XRayRecipe::Detector,
        }
    }

    /// The paper's bench for a modality at an image size ([`SceneSampling::paper_bench`]): two
    /// close-up cameras 90° apart ([`Biplane::paper_bench`]), masks thresholded from the bench
    /// photographs, and for `xray1`/`xray2` those thresholded catheters pasted onto the patch
    /// shuffle ([`XRayRecipe::Pasted`]).
    pub fn paper_bench(modality: Modality, image_size: ImageSize) -> Self {
        Self {
            scene: SceneSampling::paper_bench(),
            views: Biplane::paper_bench(image_size),
            mask: MaskRecipe::Cutout,
            xray_recipe: XRayRecipe::Pasted,
            ..Self::new(modality, image_size)
        }
    }
}

/// The side of the built-in phantom's radiograph that backgrounds are cut from, pixels.
pub const PHANTOM_SIDE_PX: usize = 512;

/// The radiographs that X-ray backgrounds are cut from, per view.
#[derive(Debug, Clone, Default)]
pub struct Backgrounds {
    /// Sources for view A and view B; a sample picks one per view at random.
    pub per_view: [Vec<BackgroundSource>; 2],
}

impl Backgrounds {
    /// The built-in phantom, rendered in each view's direction.
    pub fn phantom(views: &Biplane) -> Self {
        Self::of_views(Self::phantom_view(&views.a), Self::phantom_view(&views.b))
    }

    /// The built-in phantom rendered in `view`'s direction ([`PHANTOM_SIDE_PX`]): one view's
    /// share of [`Self::phantom`].
    pub fn phantom_view(view: &CArm) -> BackgroundSource {
        BackgroundSource::phantom(view, PHANTOM_SIDE_PX)
    }

    /// [`Self::phantom_view`] to render a band of rows at a time and make the source of with
    /// [`BackgroundSource::of_phantom`]: for callers that must answer in between (the page's
    /// thread, where one view takes about 0.1 s).
    pub fn phantom_view_in_bands(view: &CArm) -> RadiographInBands {
        BackgroundSource::phantom_in_bands(view, PHANTOM_SIDE_PX)
    }

    /// One source for each view.
    pub fn of_views(a: BackgroundSource, b: BackgroundSource) -> Self {
        Self {
            per_view: [vec![a], vec![b]],
        }
    }

    /// The same chest radiographs for both views.
    pub fn files(sources: Vec<BackgroundSource>) -> Self {
        Self {
            per_view: [sources.clone(), sources],
        }
    }
}

/// One view's pixels.
#[derive(Debug, Clone, PartialEq)]
pub enum ViewPixels {
    /// 8-bit grey (X-ray).
    Grey(Vec<u8>),
    /// 8-bit RGB (camera).
    Rgb(Vec<u8>),
}

impl ViewPixels {
    /// 1 for grey, 3 for RGB.
    pub fn channels(&self) -> usize {
        match self {
            ViewPixels::Grey(_) => 1,
            ViewPixels::Rgb(_) => 3,
        }
    }

    /// The bytes, row-major.
    pub fn bytes(&self) -> &[u8] {
        match self {
            ViewPixels::Grey(b) | ViewPixels::Rgb(b) => b,
        }
    }

    /// The pixels as 8-bit RGB, row-major (a grey value in all three channels): what H-Net
    /// reads.
    pub fn to_rgb(&self) -> Vec<u8> {
        match self {
            ViewPixels::Grey(g) => g.iter().flat_map(|&v| [v, v, v]).collect(),
            ViewPixels::Rgb(c) => c.clone(),
        }
    }
}

/// One rendered view of a sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewSample {
    /// The image.
    pub pixels: ViewPixels,
    /// The catheter mask, 8-bit coverage (255 = fully catheter).
    pub mask: Vec<u8>,
    /// Projection matrix of the view.
    pub camera: CameraMatrix,
    /// The background's source and layout (X-ray modalities).
    pub background: Option<(String, PatchLayout)>,
}

/// A complete stereo sample.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoSample {
    /// Position in the generated sequence.
    pub index: u64,
    /// The scene.
    pub params: SceneParams,
    /// The solved catheter.
    pub shape: RodShape,
    /// View A and view B.
    pub views: [ViewSample; 2],
    /// Scenes drawn before this one whose solve failed (the rod or the contact did not
    /// converge) and were dropped.
    pub dropped_draws: usize,
}

/// Why a sample could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TwinError {
    /// The rod solver failed for every draw.
    #[error("sample {index}: {attempts} scenes drawn, none solved: {last}")]
    Unsolvable {
        /// The sample.
        index: u64,
        /// Draws tried.
        attempts: usize,
        /// The last solver error.
        last: RodError,
    },
    /// No drawn actuator setting gave a contact that could be solved.
    #[error("sample {index}: {attempts} actuator settings drawn, no contact solved: {last}")]
    NoContact {
        /// The sample.
        index: u64,
        /// Draws tried.
        attempts: usize,
        /// The last contact error.
        last: ContactError,
    },
    /// An X-ray modality without a background for a view.
    #[error("no background radiograph for view {0}")]
    NoBackground(char),
}

/// The generator of sample `index` of the run seeded `seed`.
pub fn sample_rng(seed: u64, index: u64) -> ChaCha8Rng {
    // SplitMix64 finaliser of the pair: well-separated seeds for neighbouring indices.
    let mut z = seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ChaCha8Rng::seed_from_u64(z ^ (z >> 31))
}

/// Otsu's threshold of 8-bit grey values: the level that best separates two classes.
pub fn otsu_threshold(grey: &[u8]) -> u8 {
    let mut histogram = [0u64; 256];
    for &v in grey {
        histogram[v as usize] += 1;
    }
    let total = grey.len() as f64;
    let sum_all: f64 = histogram
        .iter()
        .enumerate()
        .map(|(v, &c)| v as f64 * c as f64)
        .sum();
    let (mut weight_below, mut sum_below) = (0.0, 0.0);
    let (mut best, mut best_level) = (-1.0, 0u8);
    for (level, &count) in histogram.iter().enumerate() {
        weight_below += count as f64;
        sum_below += level as f64 * count as f64;
        let weight_above = total - weight_below;
        if weight_below == 0.0 || weight_above == 0.0 {
            continue;
        }
        let mean_below = sum_below / weight_below;
        let mean_above = (sum_all - sum_below) / weight_above;
        let between = weight_below * weight_above * (mean_below - mean_above).powi(2);
        if between > best {
            best = between;
            best_level = level as u8;
        }
    }
    best_level
}

/// A binary mask (255 = catheter) of the pixels at or below `level`: the catheter is darker than
/// its surroundings in both bench photographs and fluoroscopy frames.
pub fn threshold_mask(grey: &[u8], level: u8) -> Vec<u8> {
    grey.iter()
        .map(|&v| if v <= level { 255 } else { 0 })
        .collect()
}

/// Luma of 8-bit RGB pixels (ITU-R BT.601 weights).
pub fn luma(rgb: &[u8]) -> Vec<u8> {
    rgb.chunks_exact(3)
        .map(|p| {
            ((299 * u32::from(p[0]) + 587 * u32::from(p[1]) + 114 * u32::from(p[2]) + 500) / 1000)
                as u8
        })
        .collect()
}

/// Renders one view of a solved catheter.
pub fn render_view(
    config: &TwinConfig,
    shape: &RodShape,
    view: &CArm,
    background: Option<(&BackgroundSource, PatchLayout)>,
    rng: &mut impl Rng,
) -> ViewSample {
    let tube: TubeRaster =
        render::rasterize_catheter(shape, config.rod.diameter_mm, &config.catheter, view);
    let ImageSize { width, height } = view.image_size;
    let (pixels, background, cutout) = match background {
        Some((source, layout)) => {
            let transmission =
                synthetic_xray::compose(source, &layout, &config.patches, width, height);
            let (frame, cutout) = match config.xray_recipe {
                XRayRecipe::Detector => (
                    render::render_xray(&transmission, &tube, &config.detector, rng),
                    None,
                ),
                XRayRecipe::Pasted => {
                    let (photo, cutout) = bench_photograph(config, view, &tube, rng);
                    (
                        render::paste_cutout(&transmission, &photo, &cutout),
                        Some(cutout),
                    )
                }
            };
            (
                ViewPixels::Grey(frame.to_u8()),
                Some((source.name.clone(), layout)),
                cutout,
            )
        }
        None => {
            let (photo, cutout) = bench_photograph(config, view, &tube, rng);
            (ViewPixels::Rgb(photo.to_u8()), None, Some(cutout))
        }
    };
    let geometry = || {
        GreyImage {
            width,
            height,
            data: tube.coverage.clone(),
        }
        .to_u8()
    };
    let mask = match config.mask {
        MaskRecipe::Geometry => geometry(),
        MaskRecipe::Cutout => cutout.unwrap_or_else(geometry),
        MaskRecipe::Threshold(level) => threshold_mask(&grey_of(&pixels), level),
        MaskRecipe::Otsu => {
            let grey = grey_of(&pixels);
            threshold_mask(&grey, otsu_threshold(&grey))
        }
    };
    ViewSample {
        pixels,
        mask,
        camera: view.camera_matrix(),
        background,
    }
}

/// An X-ray view of `source` with no catheter in it: the same background composition and
/// detector as [`render_view`], a random region and patch layout; 8-bit grey, `view`'s size.
/// What "no catheter found" is measured on.
pub fn render_empty_xray_view(
    config: &TwinConfig,
    view: &CArm,
    source: &BackgroundSource,
    rng: &mut impl Rng,
) -> Vec<u8> {
    let ImageSize { width, height } = view.image_size;
    let layout = PatchLayout::random(source, &config.anatomies, &config.patches, rng);
    let transmission = synthetic_xray::compose(source, &layout, &config.patches, width, height);
    let empty = TubeRaster::empty(width, height);
    render::render_xray(&transmission, &empty, &config.detector, rng).to_u8()
}

/// A bench camera's photograph of `tube` and its catheter thresholded against the empty bench.
fn bench_photograph(
    config: &TwinConfig,
    view: &CArm,
    tube: &TubeRaster,
    rng: &mut impl Rng,
) -> (RgbImage, Vec<u8>) {
    let board = render::bench_background(view, rng);
    let photo = render::render_bench(&board, tube, &config.catheter, rng);
    let cutout = render::bench_cutout(&photo, &board);
    (photo, cutout)
}

pub(super) fn grey_of(pixels: &ViewPixels) -> Vec<u8> {
    match pixels {
        ViewPixels::Grey(g) => g.clone(),
        ViewPixels::Rgb(rgb) => luma(rgb),
    }
}

/// Scene draws tried before a sample is reported unsolvable.
const MAX_DRAWS: usize = 8;

/// Generates sample `index` of the run seeded `seed`.
pub fn generate(
    config: &TwinConfig,
    backgrounds: &Backgrounds,
    seed: u64,
    index: u64,
) -> Result<StereoSample, TwinError> {
    let mut rng = sample_rng(seed, index);
    let mut last = None;
    // The plate is fixed on the bench: placed from the unloaded catheter on the nominal base.
    let plate = match &config.scene.plate {
        Some(plate) => {
            let (rod_config, base) = config.scene.nominal_scene().rod(&config.rod);
            let rest =
                rod::solve(&rod_config, &base, Vec3::ZERO).map_err(|e| TwinError::NoContact {
                    index,
                    attempts: 0,
                    last: e.into(),
                })?;
            Some((plate, base, rest))
        }
        None => None,
    };
    for dropped_draws in 0..MAX_DRAWS {
        let mut params = config.scene.sample(&mut rng);
        let (rod_config, base) = params.rod(&config.rod);
        let simulated = config.scene.rod_as_simulated(
            &params,
            rod_config,
            base,
            config.catheter.tip_electrode_mm,
        );
        let (rod_config, base, sheath_mm) = match simulated {
            Ok(simulated) => simulated,
            Err(e) => {
                last = Some(ContactError::from(e));
                continue;
            }
        };
        let solved = match (&plate, params.plate.as_mut()) {
            (Some((plate, nominal_base, nominal_rest)), Some(contact)) => {
                let pose = plate.pose(nominal_base, nominal_rest, contact);
                sensor_plate::solve(&rod_config, &base, plate, &pose, contact).map(|solution| {
                    contact.state = solution.state;
                    params.tip_force_n = solution.tip_force_n.into();
                    solution.shape
                })
            }
            _ => rod::solve(&rod_config, &base, params.tip_force_n.into())
                .map_err(ContactError::from),
        };
        match solved {
            Ok(drawn) => {
                // What the views show (a sheath's free end included); the record keeps the
                // flexible section.
                let shape = drawn.distal_from(sheath_mm);
                // View B's exposure may come after the catheter moved (drawn only then, so
                // that sets without motion are unchanged).
                let motion = config.scene.exposure_motion_mm;
                let moved = (motion > 0.0).then(|| {
                    let mut shift = || motion * (2.0 * rng.random::<f64>() - 1.0);
                    drawn.translated(Vec3::new(shift(), shift(), shift()))
                });
                let shapes = [&drawn, moved.as_ref().unwrap_or(&drawn)];
                let views = [(&config.views.a, 0usize, 'A'), (&config.views.b, 1, 'B')].map(
                    |(view, i, name)| -> Result<ViewSample, TwinError> {
                        let background = if config.modality.is_xray() {
                            let sources = &backgrounds.per_view[i];
                            if sources.is_empty() {
                                return Err(TwinError::NoBackground(name));
                            }
                            let source = &sources[rng.random_range(0..sources.len())];
                            let layout = PatchLayout::random(
                                source,
                                &config.anatomies,
                                &config.patches,
                                &mut rng,
                            );
                            Some((source, layout))
                        } else {
                            None
                        };
                        Ok(render_view(config, shapes[i], view, background, &mut rng))
                    },
                );
                let [a, b] = views;
                return Ok(StereoSample {
                    index,
                    params,
                    shape,
                    views: [a?, b?],
                    dropped_draws,
                });
            }
            Err(e) => last = Some(e),
        }
    }
    let last = last.expect("at least one draw");
    Err(match last {
        ContactError::Rod(last) if plate.is_none() => TwinError::Unsolvable {
            index,
            attempts: MAX_DRAWS,
            last,
        },
        last => TwinError::NoContact {
            index,
            attempts: MAX_DRAWS,
            last,
        },
    })
}
