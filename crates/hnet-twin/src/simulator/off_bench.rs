//! Pairs drawn off the bench: any catheter and base pose the [`SceneSampling::varied`] preset
//! draws, seen from any C-arm angles the page lets a user set ([`crate::simulator::carm::VIEW_A_PRIMARY_DEG`]
//! and the ranges beside it), on the thorax phantom rendered from about those angles or on chest
//! radiographs. What the shipped network's masks must hold on; the shape no longer follows from
//! the force alone (a stiffer catheter bends less), so such pairs teach masks, not force.

use std::collections::HashMap;
use std::sync::Mutex;

use rand::RngExt;

use crate::simulator::carm::{
    Biplane, CArm, SECONDARY_DEG, VIEW_A_PRIMARY_DEG, VIEW_B_PRIMARY_DEG,
};
use crate::simulator::scene::{
    Backgrounds, SceneSampling, StereoSample, TwinConfig, TwinError, generate, sample_rng,
};
use crate::simulator::synthetic_xray::BackgroundSource;

/// Step of the grid of C-arm angles at which the thorax phantom is rendered, degrees: a view
/// takes the phantom of the nearest grid angles (a background only has to look like a thorax
/// seen from about there).
const PHANTOM_GRID_DEG: f64 = 20.0;

/// Side of a rendered phantom radiograph, pixels (as [`Backgrounds::phantom`]).
const PHANTOM_SIZE_PX: usize = 512;

/// Keeps the off-bench draws independent of a bench run's with the same seed.
const OFF_BENCH_SALT: u64 = 0x6F66_665F_6265_6E63;

/// The generator of off-bench pairs.
pub struct OffBench {
    twin: TwinConfig,
    radiographs: Vec<BackgroundSource>,
    radiograph_fraction: f64,
    phantoms: Mutex<HashMap<(i32, i32), BackgroundSource>>,
}

impl std::fmt::Debug for OffBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OffBench")
            .field("radiographs", &self.radiographs.len())
            .field("radiograph_fraction", &self.radiograph_fraction)
            .finish_non_exhaustive()
    }
}

impl OffBench {
    /// Off-bench pairs with `twin`'s look (modality, detector, catheter, image size): a
    /// `radiograph_fraction` of them on one of `radiographs` (when there are any), the rest on
    /// the phantom.
    pub fn new(
        twin: TwinConfig,
        radiographs: Vec<BackgroundSource>,
        radiograph_fraction: f64,
    ) -> Self {
        Self {
            twin: TwinConfig {
                scene: SceneSampling::varied(),
                ..twin
            },
            radiographs,
            radiograph_fraction,
            phantoms: Mutex::new(HashMap::new()),
        }
    }

    /// The same generator drawing its scenes from `scenes` instead of the
    /// [`SceneSampling::varied`] preset (checked with [`SceneSampling::check`] by its caller).
    pub fn with_scenes(mut self, scenes: SceneSampling) -> Self {
        self.twin.scene = scenes;
        self
    }

    /// Its twin settings: the look it was given, with the scenes it draws (each pair's views are
    /// its own, [`Self::draw`]).
    pub fn twin(&self) -> &TwinConfig {
        &self.twin
    }

    /// The chest radiographs it draws on.
    pub fn radiographs(&self) -> usize {
        self.radiographs.len()
    }

    /// The twin settings (with pair `index`'s two views) and the backgrounds of off-bench pair
    /// `index` of the run seeded `seed`.
    pub fn draw(&self, seed: u64, index: u64) -> (TwinConfig, Backgrounds) {
        let mut rng = sample_rng(seed ^ OFF_BENCH_SALT, index);
        let mut within = |[lo, hi]: [f64; 2]| lo + (hi - lo) * rng.random::<f64>();
        let size = self.twin.image_size;
        let views = Biplane {
            a: CArm::cardiac(within(VIEW_A_PRIMARY_DEG), within(SECONDARY_DEG), size),
            b: CArm::cardiac(within(VIEW_B_PRIMARY_DEG), within(SECONDARY_DEG), size),
        };
        let on_radiograph =
            !self.radiographs.is_empty() && rng.random::<f64>() < self.radiograph_fraction;
        let backgrounds = if on_radiograph {
            Backgrounds::files(self.radiographs.clone())
        } else {
            Backgrounds {
                per_view: [self.phantom_near(&views.a), self.phantom_near(&views.b)],
            }
        };
        let twin = TwinConfig {
            views,
            ..self.twin.clone()
        };
        (twin, backgrounds)
    }

    /// Off-bench pair `index` of the run seeded `seed`, with the twin settings it was made with.
    pub fn generate(&self, seed: u64, index: u64) -> Result<(TwinConfig, StereoSample), TwinError> {
        let (twin, backgrounds) = self.draw(seed, index);
        let sample = generate(&twin, &backgrounds, seed ^ OFF_BENCH_SALT, index)?;
        Ok((twin, sample))
    }

    /// The phantom rendered at the grid angles nearest to `view`'s (rendered once, then kept).
    fn phantom_near(&self, view: &CArm) -> Vec<BackgroundSource> {
        let snap = |deg: f64| (deg / PHANTOM_GRID_DEG).round() as i32;
        let key = (snap(view.primary_deg), snap(view.secondary_deg));
        let mut cache = self.phantoms.lock().unwrap_or_else(|e| e.into_inner());
        let source = cache.entry(key).or_insert_with(|| {
            let at = CArm::cardiac(
                f64::from(key.0) * PHANTOM_GRID_DEG,
                f64::from(key.1) * PHANTOM_GRID_DEG,
                view.image_size,
            );
            BackgroundSource::phantom(&at, PHANTOM_SIZE_PX)
        });
        vec![source.clone()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::scene::Modality;
    use hnet_units::ImageSize;

    /// A small flat radiograph: rendering the phantom at 512 px takes seconds in a debug build
    /// (the phantom path runs in the training stream's test).
    fn flat_radiograph() -> BackgroundSource {
        BackgroundSource::chest_radiograph(
            "flat",
            crate::simulator::raster::GreyImage::filled(64, 64, 0.5),
        )
    }

    #[test]
    fn off_bench_pairs_are_seeded_and_inside_the_pages_angles() {
        let twin = TwinConfig::new(Modality::Xray2, ImageSize::square(32));
        let off = OffBench::new(twin, vec![flat_radiograph()], 1.0);
        for index in 0..4 {
            let (twin, sample) = off.generate(3, index).unwrap();
            let (again, same) = off.generate(3, index).unwrap();
            assert_eq!((twin.views, &sample), (again.views, &same));
            let inside = |deg: f64, [lo, hi]: [f64; 2]| (lo..=hi).contains(&deg);
            assert!(inside(twin.views.a.primary_deg, VIEW_A_PRIMARY_DEG));
            assert!(inside(twin.views.b.primary_deg, VIEW_B_PRIMARY_DEG));
            assert!(inside(twin.views.a.secondary_deg, SECONDARY_DEG));
            assert!(
                SceneSampling::varied()
                    .departures(&sample.params)
                    .is_empty()
            );
            assert!(sample.views.iter().all(|v| v.mask.iter().any(|&m| m > 0)));
        }
        // Other scenes, when asked for: here only the longest catheters.
        let long = SceneSampling {
            length_mm: [55.0, 60.0],
            ..SceneSampling::varied()
        };
        assert_eq!(long.check(), Ok(()));
        let off = off.with_scenes(long.clone());
        let (_, sample) = off.generate(3, 0).unwrap();
        assert!(long.departures(&sample.params).is_empty());
        assert!(sample.params.length_mm >= 55.0);
        let reversed = SceneSampling {
            length_mm: [60.0, 55.0],
            ..long
        };
        assert!(reversed.check().unwrap_err().starts_with("length_mm"));
    }
}
