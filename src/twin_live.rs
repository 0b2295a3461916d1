//! The digital twin in the page: sliders for the tip force, the catheter and the C-arm, and the
//! synthetic X-ray background composer. Every image comes from `hnet-twin`, the same code
//! `hnet simulate` runs; only the choice of parameters is the user's.

use hnet_twin::simulator::carm::{Biplane, CArm};
use hnet_twin::simulator::raster::{GreyImage, Rect};
use hnet_twin::simulator::rod;
use hnet_twin::simulator::scene::{
    Modality, PAPER_BENCH, SceneParams, SceneSampling, TwinConfig, render_view,
};
use hnet_twin::simulator::sensor_plate::{self, ContactError, ContactState, PlateContact};
use hnet_twin::simulator::synthetic_xray::{
    Anatomy, BackgroundSource, PatchLayout, PatchRule, compose,
};
use hnet_twin::vec3::Vec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::imaging::WORK_SIZE;
use crate::workspace::{LabeledPair, PairSource};
use hnet_units::{ImageSize, TipForce};

/// The twin's sliders.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwinControls {
    /// Tip force `(Fx, Fy, Fz)` in newtons, world frame (x: patient left, y: anterior, z:
    /// cranial).
    pub force_n: TipForce,
    /// Bending stiffness EI in 10⁻³ N·m².
    pub stiffness_mn_m2: f64,
    /// Flexible length, mm.
    pub length_mm: f64,
    /// Bend radius of the pre-curve, mm (0: a straight catheter).
    pub precurve_radius_mm: f64,
    /// Image look.
    pub modality: Modality,
    /// View A primary (LAO+) and secondary (cranial+) angles, degrees.
    pub view_a_deg: [f64; 2],
    /// View B primary and secondary angles, degrees.
    pub view_b_deg: [f64; 2],
    /// Seed of the image noise.
    pub noise_seed: u64,
    /// The paper's bench instead of the C-arm: the close-up cameras, and the tip pressed against
    /// the sensor plate set by these actuators (the force is then read from the contact, not
    /// set by `force_n`).
    pub paper_bench: Option<PlateContact>,
}

/// The plate's actuators when the page switches to the paper's bench: a 2 mm press slid 1 mm.
pub const DEFAULT_PLATE: PlateContact = PlateContact {
    tilt_deg: 10.0,
    tilt_azimuth_deg: 0.0,
    press_mm: 2.0,
    slide_mm: 1.0,
    slide_azimuth_deg: 45.0,
    state: ContactState::Free,
};

impl Default for TwinControls {
    fn default() -> Self {
        Self {
            force_n: TipForce::new(0.15, 0.05, -0.10),
            stiffness_mn_m2: 0.6,
            length_mm: 50.0,
            precurve_radius_mm: 60.0,
            modality: Modality::Xray2,
            view_a_deg: [0.0, 0.0],
            view_b_deg: [90.0, 0.0],
            noise_seed: 1,
            paper_bench: None,
        }
    }
}

impl TwinControls {
    /// The two views at the working size: a biplane cardiac C-arm for X-ray, the bench cameras
    /// for RGB.
    pub fn views(&self) -> Biplane {
        if self.paper_bench.is_some() {
            return Biplane::paper_bench(WORK_SIZE);
        }
        let make = |deg: [f64; 2]| -> CArm {
            if self.modality.is_xray() {
                CArm::cardiac(deg[0], deg[1], WORK_SIZE)
            } else {
                CArm::bench_camera(deg[0], deg[1], WORK_SIZE)
            }
        };
        Biplane {
            a: make(self.view_a_deg),
            b: make(self.view_b_deg),
        }
    }

    /// The scene: the twin's nominal base pose with these mechanics.
    pub fn scene(&self) -> SceneParams {
        SceneParams {
            tip_force_n: self.force_n,
            bending_stiffness_n_m2: self.stiffness_mn_m2 * 1e-3,
            length_mm: self.length_mm,
            precurvature_per_mm: if self.precurve_radius_mm > 0.0 {
                1.0 / self.precurve_radius_mm
            } else {
                0.0
            },
            base_position_mm: self.sampling().base_position_mm,
            base_tilt_deg: 0.0,
            base_azimuth_deg: 0.0,
            base_roll_deg: 90.0,
            plate: self.paper_bench,
            wall_normal: None,
        }
    }

    /// The preset these controls are a scene of: the twin's C-arm bench or the paper's bench.
    pub fn sampling(&self) -> SceneSampling {
        if self.paper_bench.is_some() {
            SceneSampling::paper_bench()
        } else {
            SceneSampling::bench()
        }
    }

    /// Solves the rod and renders both views (X-ray modalities on `background`), with the
    /// twin's exact masks and the true force as the labels.
    ///
    /// On the paper's bench the plate's actuators set the contact and the force is read from it
    /// (the fixture at its nominal pose, the plate placed from it, as `hnet simulate --scenes
    /// paper-bench` does).
    pub fn render(
        &self,
        id: String,
        background: &XrayBackground,
    ) -> Result<LabeledPair, ContactError> {
        let mut config = match self.paper_bench {
            Some(_) => TwinConfig::paper_bench(self.modality, WORK_SIZE),
            None => TwinConfig::new(self.modality, WORK_SIZE),
        };
        config.views = self.views();
        config.patches = background.rule();
        let mut scene = self.scene();
        let (rod_config, base) = scene.rod(&config.rod);
        let shape = match (&config.scene.plate, scene.plate.as_mut()) {
            (Some(plate), Some(contact)) => {
                let rest = rod::solve(&rod_config, &base, Vec3::ZERO)?;
                let pose = plate.pose(&base, &rest, contact);
                let solved = sensor_plate::solve(&rod_config, &base, plate, &pose, contact)?;
                contact.state = solved.state;
                scene.tip_force_n = solved.tip_force_n.into();
                solved.shape
            }
            _ => rod::solve(&rod_config, &base, scene.tip_force_n.into())?,
        };
        let force_n = scene.tip_force_n;
        let mut rng = ChaCha8Rng::seed_from_u64(self.noise_seed);
        let layouts = background.layouts();
        let mut views = Vec::with_capacity(2);
        for (view, layout) in config.views.views().into_iter().zip(layouts) {
            let bg = self
                .modality
                .is_xray()
                .then_some((&background.source, layout));
            views.push(render_view(&config, &shape, view, bg, &mut rng));
        }
        let mut settings = serde_json::json!({
            "modality": self.modality.name(),
            "scene": scene,
            "background": self.modality.is_xray().then(|| serde_json::json!({
                "source": background.source.name,
                "style": background.style.name(),
                "region": background.region,
                "seed": background.seed,
            })),
            "noise_seed": self.noise_seed,
        });
        if self.paper_bench.is_some() {
            settings["preset"] = PAPER_BENCH.into();
        }
        let mut pair = LabeledPair::new(
            id,
            PairSource::Twin {
                true_force_n: force_n,
                tip_mm: shape.tip_mm().0,
                views: config.views,
                settings,
            },
            views[0].pixels.to_rgb(),
            views[1].pixels.to_rgb(),
        );
        // The twin knows the exact masks and force: they are the labels.
        pair.mask_a = hnet_units::mask::binarize_labels(&views[0].mask);
        pair.mask_b = hnet_units::mask::binarize_labels(&views[1].mask);
        pair.masks_labeled = true;
        pair.force_n = Some(force_n);
        pair.force_origin = hnet_twin::dataset::label_origin::LabelOrigin::Simulated;
        Ok(pair)
    }
}

/// The paper's two synthetic X-ray styles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XrayStyle {
    /// XRay-1: consistently bright patches (easy).
    Xray1,
    /// XRay-2: a random mix of dark and bright patches (hard).
    Xray2,
}

impl XrayStyle {
    /// `xray1` or `xray2`.
    pub fn name(self) -> &'static str {
        match self {
            XrayStyle::Xray1 => "xray1",
            XrayStyle::Xray2 => "xray2",
        }
    }

    /// The twin's modality of this style.
    pub fn modality(self) -> Modality {
        match self {
            XrayStyle::Xray1 => Modality::Xray1,
            XrayStyle::Xray2 => Modality::Xray2,
        }
    }

    /// The patch rule behind the style (the same rules `hnet simulate` uses).
    pub fn rule(self) -> PatchRule {
        match self {
            XrayStyle::Xray1 => PatchRule::xray1(),
            XrayStyle::Xray2 => PatchRule::xray2(),
        }
    }
}

/// A synthetic X-ray background as the composer sets it up: a radiograph, a square region of
/// it, and the seed of the patch shuffle. View A and view B get two different shuffles of the
/// same region.
#[derive(Debug, Clone)]
pub struct XrayBackground {
    /// The radiograph (bright = dense).
    pub source: BackgroundSource,
    /// The cropped region, normalised source coordinates `[x0, y0, x1, y1]`.
    pub region: Rect,
    /// Seed of the patch order and of which patches are dark.
    pub seed: u64,
    /// XRay-1 or XRay-2.
    pub style: XrayStyle,
}

/// Side of the default region, as a fraction of the radiograph's shorter side.
pub const DEFAULT_REGION_SIDE: f64 = 0.34;

impl XrayBackground {
    /// The built-in thorax phantom seen frontally (512 px), region on the heart.
    pub fn phantom() -> Self {
        let source = BackgroundSource::phantom(&CArm::cardiac(0.0, 0.0, WORK_SIZE), 512);
        Self::on_heart(source)
    }

    /// A chest radiograph the user gave (a frontal PA view), region on the heart.
    pub fn radiograph(name: &str, image: GreyImage) -> Self {
        Self::on_heart(BackgroundSource::chest_radiograph(name, image))
    }

    fn on_heart(source: BackgroundSource) -> Self {
        let centre = source.region_centre(Anatomy::Heart).unwrap_or([0.5, 0.5]);
        let region = source.square_region(centre, DEFAULT_REGION_SIDE);
        Self {
            source,
            region,
            seed: 1,
            style: XrayStyle::Xray2,
        }
    }

    /// The patch rule of the chosen style.
    pub fn rule(&self) -> PatchRule {
        self.style.rule()
    }

    /// Moves the region so that its centre is at `centre` (normalised), keeping its size and
    /// keeping it inside the radiograph.
    pub fn move_region_to(&mut self, centre: [f64; 2]) {
        let [x0, y0, x1, y1] = self.region.0;
        let (w, h) = (x1 - x0, y1 - y0);
        let cx = centre[0].clamp(w / 2.0, 1.0 - w / 2.0);
        let cy = centre[1].clamp(h / 2.0, 1.0 - h / 2.0);
        self.region = Rect([cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0]);
    }

    /// Resizes the region to a square of `side` (fraction of the shorter side) around its
    /// centre.
    pub fn resize_region(&mut self, side: f64) {
        let [x0, y0, x1, y1] = self.region.0;
        let centre = [(x0 + x1) / 2.0, (y0 + y1) / 2.0];
        self.region = self.source.square_region(centre, side.clamp(0.05, 1.0));
        self.move_region_to(centre);
    }

    /// The region's side as a fraction of the shorter side of the radiograph.
    pub fn region_side(&self) -> f64 {
        let image = &self.source.image;
        let shorter = image.width.min(image.height) as f64;
        (self.region.0[2] - self.region.0[0]) * image.width as f64 / shorter
    }

    /// The patch layouts of view A and view B: the region, with two seeded shuffles.
    pub fn layouts(&self) -> [PatchLayout; 2] {
        let rule = self.rule();
        let cells = rule.grid * rule.grid;
        let base = PatchLayout {
            anatomy: None,
            region: self.region,
            permutation: (0..cells as u8).collect(),
            dark: vec![false; cells],
            grid_offset: [0.0; 2],
        };
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let a = base.reshuffled(&rule, &mut rng);
        let b = base.reshuffled(&rule, &mut rng);
        [a, b]
    }

    /// Both views' backgrounds as transmission maps of `size` pixels (1 = nothing absorbs).
    pub fn compose(&self, size: ImageSize) -> [GreyImage; 2] {
        let rule = self.rule();
        self.layouts()
            .map(|layout| compose(&self.source, &layout, &rule, size.width, size.height))
    }
}

// Native tests (`cargo test`); the browser tests are in tests/web.rs.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    #[test]
    fn the_twin_pair_carries_its_exact_labels() {
        let controls = TwinControls::default();
        let background = XrayBackground::phantom();
        let pair = controls.render("pair-0001".into(), &background).unwrap();
        assert_eq!(pair.view_a.len(), WORK_SIZE.pixels() * 3);
        assert!(pair.is_complete());
        assert_eq!(pair.force_n, Some(TipForce::new(0.15, 0.05, -0.10)));
        // The catheter is visible in both views, and darker than its surroundings (X-ray).
        for view in crate::workspace::View::BOTH {
            let n = pair.labeled_pixels(view);
            assert!(n > 200, "{view:?}: {n} catheter pixels");
        }
        // The same settings give the same pair; another force bends the catheter elsewhere.
        assert_eq!(
            controls.render("pair-0001".into(), &background).unwrap(),
            pair
        );
        let pushed = TwinControls {
            force_n: TipForce::new(-0.3, 0.0, 0.0),
            ..controls
        }
        .render("pair-0001".into(), &background)
        .unwrap();
        assert_ne!(pushed.mask_a, pair.mask_a);
    }

    #[test]
    fn on_the_papers_bench_the_force_is_read_from_the_plate() {
        let controls = TwinControls {
            paper_bench: Some(DEFAULT_PLATE),
            ..TwinControls::default()
        };
        let pair = controls
            .render("bench".into(), &XrayBackground::phantom())
            .unwrap();
        let PairSource::Twin {
            true_force_n,
            views,
            settings,
            ..
        } = &pair.source
        else {
            panic!("a twin pair")
        };
        assert_eq!(*views, Biplane::paper_bench(WORK_SIZE));
        assert_eq!(settings["preset"], PAPER_BENCH);
        assert_ne!(settings["scene"]["plate"]["state"], "free");
        // Not the force sliders' value: the contact's.
        assert_ne!(*true_force_n, controls.force_n);
        assert!(true_force_n.max_abs() > 0.01);
        assert_eq!(pair.force_n, Some(*true_force_n));
    }

    #[test]
    fn shuffles_are_seeded_and_differ_between_views() {
        let mut bg = XrayBackground::phantom();
        let [a, b] = bg.layouts();
        assert_ne!(a.permutation, b.permutation);
        assert_eq!(bg.layouts(), [a.clone(), b]);
        bg.seed = 2;
        assert_ne!(bg.layouts()[0].permutation, a.permutation);
        // XRay-1 has no dark patches; XRay-2 some.
        bg.style = XrayStyle::Xray1;
        assert!(bg.layouts().iter().all(|l| l.dark.iter().all(|d| !d)));
        bg.style = XrayStyle::Xray2;
        assert!(bg.layouts().iter().any(|l| l.dark.iter().any(|d| *d)));
    }

    #[test]
    fn the_region_stays_inside_the_radiograph() {
        let mut bg = XrayBackground::phantom();
        bg.move_region_to([0.0, 1.0]);
        let [x0, y0, x1, y1] = bg.region.0;
        assert!(x0 >= 0.0 && y1 <= 1.0 + 1e-12 && x1 > x0 && y1 > y0);
        bg.resize_region(0.5);
        assert!((bg.region_side() - 0.5).abs() < 1e-9);
        let [a, _] = bg.compose(ImageSize::new(64, 48));
        assert_eq!((a.width, a.height), (64, 48));
        assert!(a.data.iter().all(|t| (0.0..=1.0).contains(t)));
    }
}
