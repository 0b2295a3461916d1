//! Training pairs simulated by the catheter twin while the network trains.
//!
//! Every epoch sees pairs it never saw before: pair `j` of epoch `e` is the twin's sample
//! `e·pairs_per_epoch + j` of the stream's seed, so a run is the same whether it ran in one go or
//! was resumed, and data volume stops being bounded by what fits on disk. The bench pairs are
//! made with the twin settings the dataset given to `hnet train --data` was simulated with (its
//! val and test splits stay the fixed yardstick), rendered at that dataset's size and reduced to
//! the network's exactly as a file read back from it would be.
//!
//! A share of pairs can be drawn *off the bench*: random catheters and base poses (the twin's
//! `varied` scenes), random C-arm angles within the page's ranges, on the thorax phantom or on
//! real chest radiographs. Their shape no longer follows from the force alone, so they carry
//! their masks but not their force: the loss learns segmentation from them and force from the
//! bench pairs only.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, bail};
use burn::data::dataloader::{DataLoader, DataLoaderIterator};
use burn::data::dataset::{Dataset as BurnDataset, DatasetError};
use burn::tensor::Device;
use hnet_twin::dataset::simulate::OFF_BENCH_VIEWS;
use hnet_twin::dataset::{Dataset, LoadedPair, SquareSymmetry};
use hnet_twin::simulator::off_bench::OffBench;
use hnet_twin::simulator::render::DetectorRanges;
use hnet_twin::simulator::scene::{Backgrounds, SceneSampling, TwinConfig, generate, sample_rng};
use hnet_units::ImageSize;
use rand::RngExt;
use serde::{Deserialize, Serialize};

use super::StereoItem;
use crate::simulate::radiographs;

/// Settings of a training stream (`stream` in a training config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TwinStreamConfig {
    /// Fresh pairs per epoch.
    pub pairs_per_epoch: usize,
    /// Seed of the stream's pairs; must differ from the dataset's, whose val and test pairs
    /// would otherwise come back as training pairs.
    pub seed: u64,
    /// Pairs drawn off the bench, for the masks (none when absent).
    #[serde(default)]
    pub off_bench: Option<OffBenchConfig>,
    /// Bench pairs imaged by other X-ray detectors (dose, blur, scatter and glare, display
    /// curve), for masks and force that hold up on other systems (none when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imaging: Option<ImagingConfig>,
    /// Fraction of pairs, bench and off-bench, whose X-ray background's patch grid starts
    /// anywhere (`hnet simulate --random-patch-grid`) instead of where the dataset's does, in
    /// `[0, 1]`: one run trains on both grids (0, the default, keeps the dataset's).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub random_patch_grid_fraction: f64,
}

fn is_zero(fraction: &f64) -> bool {
    *fraction == 0.0
}

/// The share of bench pairs imaged by a detector drawn per pair, and the detectors' ranges.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImagingConfig {
    /// Fraction of bench pairs imaged by a drawn detector, in `[0, 1]` (the others by the
    /// dataset's).
    pub fraction: f64,
    /// The detectors drawn from.
    pub detectors: DetectorRanges,
}

/// The share and the look of off-bench pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OffBenchConfig {
    /// Fraction of each epoch's pairs drawn off the bench, in `[0, 1]`.
    pub fraction: f64,
    /// Chest radiographs (image files or folders of them) to cut backgrounds from; relative
    /// paths are from the folder `hnet train` runs in. Without any, every off-bench pair is on
    /// the thorax phantom.
    #[serde(default)]
    pub radiographs: Vec<PathBuf>,
    /// Fraction of off-bench pairs on a radiograph rather than the phantom, when radiographs
    /// are given.
    #[serde(default = "half")]
    pub radiograph_fraction: f64,
    /// The catheters and poses off-bench pairs draw (every field of a
    /// [`hnet_twin::simulator::scene::SceneSampling`]); the twin's `varied` preset when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenes: Option<SceneSampling>,
    /// Each off-bench view, image and mask together, carried by one of the square's eight
    /// symmetries (quarter turns, mirror) drawn for it: the masks then see catheters cross the
    /// image at every angle, where the bench's stand mostly upright. Square networks only.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub turned_views: bool,
}

fn half() -> f64 {
    0.5
}

impl TwinStreamConfig {
    /// Checks the settings alone (the dataset is checked by [`TwinStream::new`]).
    pub fn check(&self) -> anyhow::Result<()> {
        if self.pairs_per_epoch == 0 {
            bail!("stream.pairs_per_epoch must be at least 1");
        }
        if let Some(off) = &self.off_bench
            && !((0.0..=1.0).contains(&off.fraction)
                && (0.0..=1.0).contains(&off.radiograph_fraction))
        {
            bail!("stream.off_bench's fractions must lie in [0, 1]");
        }
        if let Some(scenes) = self.off_bench.as_ref().and_then(|o| o.scenes.as_ref()) {
            scenes
                .check()
                .map_err(|why| anyhow::anyhow!("stream.off_bench.scenes: {why}"))?;
        }
        if let Some(imaging) = &self.imaging {
            if !(0.0..=1.0).contains(&imaging.fraction) {
                bail!("stream.imaging.fraction must lie in [0, 1]");
            }
            imaging
                .detectors
                .check()
                .map_err(|why| anyhow::anyhow!("stream.imaging.detectors: {why}"))?;
        }
        if !(0.0..=1.0).contains(&self.random_patch_grid_fraction) {
            bail!("stream.random_patch_grid_fraction must lie in [0, 1]");
        }
        Ok(())
    }
}

/// Keeps the choice between a bench and an off-bench pair independent of both pairs' draws.
const MIX_SALT: u64 = 0x6D69_785F_7061_6972;

/// Keeps the symmetries of an off-bench pair's views independent of the pair's own draws.
const SYMMETRY_SALT: u64 = 0x7475_726E_5F76_6965;

/// Keeps a bench pair's drawn detector independent of the pair's own draws.
const IMAGING_SALT: u64 = 0x696D_6167_696E_6721;

/// Keeps the choice of a pair's patch grid independent of the pair's own draws.
const PATCH_GRID_SALT: u64 = 0x6772_6964_5F61_6E79;

/// The twin settings and off-bench draws of one patch grid.
struct Look {
    twin: TwinConfig,
    off_bench: Option<OffBench>,
}

/// The twin's training pairs for the epoch in progress (a Burn dataset).
pub struct TwinStream {
    config: TwinStreamConfig,
    /// The dataset's look.
    dataset_look: Look,
    /// The look with the patch grid anywhere, when `random_patch_grid_fraction` asks for it.
    grid_anywhere: Option<Look>,
    bench_backgrounds: Backgrounds,
    size: ImageSize,
    epochs_started: Arc<AtomicUsize>,
}

impl std::fmt::Debug for TwinStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TwinStream")
            .field("config", &self.config)
            .field("size", &self.size)
            .finish_non_exhaustive()
    }
}

impl TwinStream {
    /// The stream of `config` for a network of input `size`, reproducing the twin settings of
    /// `dataset`; `epochs_done` epochs are already trained (a resumed run continues the
    /// stream where it stopped).
    pub fn new(
        config: &TwinStreamConfig,
        dataset: &Dataset,
        size: ImageSize,
        epochs_done: usize,
    ) -> anyhow::Result<Self> {
        config.check()?;
        let header_file = dataset.root.join("dataset.json");
        let source = &dataset.header.source;
        let twin: TwinConfig = source
            .get("twin")
            .cloned()
            .context("it records no twin settings (it was not made by `hnet simulate`)")
            .and_then(|t| serde_json::from_value(t).context("its twin settings do not parse"))
            .with_context(|| {
                format!(
                    "stream: cannot reproduce '{}' with the twin",
                    header_file.display()
                )
            })?;
        if source.get("views").and_then(|v| v.as_str()) == Some(OFF_BENCH_VIEWS) {
            bail!(
                "stream: '{}' holds off-bench pairs, whose force is not a label; give a bench \
                 dataset to --data (off-bench pairs go in stream.off_bench)",
                header_file.display()
            );
        }
        if source.get("seed").and_then(|s| s.as_u64()) == Some(config.seed) {
            bail!(
                "stream.seed {} is the seed of '{}': its val and test pairs would be trained on; \
                 choose another",
                config.seed,
                dataset.root.display()
            );
        }
        let on_phantom = source
            .get("backgrounds")
            .and_then(|b| b.as_array())
            .is_none_or(|names| {
                names
                    .iter()
                    .all(|n| n.as_str().is_some_and(|n| n.starts_with("phantom:")))
            });
        if twin.modality.is_xray() && !on_phantom {
            bail!(
                "stream: '{}' was simulated on radiograph backgrounds; the stream reproduces \
                 datasets simulated on the thorax phantom (radiographs go in \
                 stream.off_bench.radiographs)",
                header_file.display()
            );
        }
        if config
            .off_bench
            .as_ref()
            .is_some_and(|off| off.turned_views)
            && size.width != size.height
        {
            bail!(
                "stream.off_bench.turned_views needs a square network; this one is {}×{}",
                size.width,
                size.height
            );
        }
        if config.random_patch_grid_fraction > 0.0 && !twin.modality.is_xray() {
            bail!(
                "stream.random_patch_grid_fraction is for X-ray datasets; '{}' is {:?}",
                header_file.display(),
                twin.modality
            );
        }
        let look = |twin: TwinConfig| -> anyhow::Result<Look> {
            let off_bench = match &config.off_bench {
                Some(off) => {
                    let (radiographs, _) =
                        radiographs(&off.radiographs).context("stream.off_bench.radiographs")?;
                    let off_bench =
                        OffBench::new(twin.clone(), radiographs, off.radiograph_fraction);
                    Some(match &off.scenes {
                        Some(scenes) => off_bench.with_scenes(scenes.clone()),
                        None => off_bench,
                    })
                }
                None => None,
            };
            Ok(Look { twin, off_bench })
        };
        let grid_anywhere = if config.random_patch_grid_fraction > 0.0 {
            let mut anywhere = twin.clone();
            anywhere.patches.random_grid_offset = true;
            Some(look(anywhere)?)
        } else {
            None
        };
        Ok(Self {
            config: config.clone(),
            bench_backgrounds: Backgrounds::phantom(&twin.views),
            dataset_look: look(twin)?,
            grid_anywhere,
            size,
            epochs_started: Arc::new(AtomicUsize::new(epochs_done)),
        })
    }

    /// The counter of epochs begun, which [`EpochCounting`] advances.
    pub fn epochs_started(&self) -> Arc<AtomicUsize> {
        self.epochs_started.clone()
    }

    /// Pairs per epoch.
    pub fn pairs_per_epoch(&self) -> usize {
        self.config.pairs_per_epoch
    }

    /// What the stream trains on, in a line.
    pub fn describe(&self) -> String {
        let off_bench = match &self.config.off_bench {
            Some(off) => format!(
                ", {:.0} % off the bench ({} radiographs{})",
                off.fraction * 100.0,
                self.dataset_look
                    .off_bench
                    .as_ref()
                    .map_or(0, OffBench::radiographs),
                if off.turned_views {
                    ", views turned"
                } else {
                    ""
                }
            ),
            None => String::new(),
        };
        let grid = if self.grid_anywhere.is_some() {
            format!(
                ", {:.0} % with the patch grid anywhere",
                self.config.random_patch_grid_fraction * 100.0
            )
        } else {
            String::new()
        };
        format!(
            "{} fresh twin pairs per epoch (stream seed {}{off_bench}{grid})",
            self.config.pairs_per_epoch, self.config.seed
        )
    }

    /// Pair `index` of the stream (over all epochs).
    pub fn pair(&self, index: u64) -> anyhow::Result<StereoItem> {
        let off_bench = self.config.off_bench.as_ref().is_some_and(|off| {
            sample_rng(self.config.seed ^ MIX_SALT, index).random::<f64>() < off.fraction
        });
        let look = match &self.grid_anywhere {
            Some(anywhere)
                if sample_rng(self.config.seed ^ PATCH_GRID_SALT, index).random::<f64>()
                    < self.config.random_patch_grid_fraction =>
            {
                anywhere
            }
            _ => &self.dataset_look,
        };
        let sample = match look.off_bench.as_ref().filter(|_| off_bench) {
            Some(off) => off.generate(self.config.seed, index)?.1,
            None => {
                let mut rng = sample_rng(self.config.seed ^ IMAGING_SALT, index);
                match self
                    .config
                    .imaging
                    .filter(|i| rng.random::<f64>() < i.fraction)
                {
                    Some(imaging) => {
                        let twin = TwinConfig {
                            detector: imaging.detectors.draw(&mut rng),
                            ..look.twin.clone()
                        };
                        generate(&twin, &self.bench_backgrounds, self.config.seed, index)?
                    }
                    None => generate(&look.twin, &self.bench_backgrounds, self.config.seed, index)?,
                }
            }
        };
        let mut pair = LoadedPair::from_sample(&sample, look.twin.image_size, self.size);
        if off_bench
            && self
                .config
                .off_bench
                .as_ref()
                .is_some_and(|o| o.turned_views)
        {
            let mut rng = sample_rng(self.config.seed ^ SYMMETRY_SALT, index);
            pair = pair.with_symmetries([
                SquareSymmetry::nth(rng.random::<u64>()),
                SquareSymmetry::nth(rng.random::<u64>()),
            ]);
        }
        let force = sample.params.tip_force_n;
        Ok(StereoItem::new(
            pair,
            force,
            !off_bench,
            format!("stream-{}-{index}", self.config.seed),
        ))
    }
}

impl BurnDataset<StereoItem> for TwinStream {
    fn get(&self, index: usize) -> Result<StereoItem, DatasetError> {
        let epoch = self
            .epochs_started
            .load(Ordering::Relaxed)
            .saturating_sub(1);
        let global = (epoch * self.config.pairs_per_epoch + index) as u64;
        self.pair(global)
            .map_err(|e| DatasetError::new(std::io::Error::other(format!("{e:#}"))))
    }

    fn len(&self) -> usize {
        self.config.pairs_per_epoch
    }
}

/// A data loader that counts the epochs it is iterated for, so that a [`TwinStream`] behind it
/// serves the next epoch's pairs.
pub struct EpochCounting<O> {
    inner: Arc<dyn DataLoader<O>>,
    epochs_started: Arc<AtomicUsize>,
}

impl<O> EpochCounting<O> {
    /// Wraps `inner`, advancing `epochs_started` each time an epoch's iteration begins.
    pub fn new(inner: Arc<dyn DataLoader<O>>, epochs_started: Arc<AtomicUsize>) -> Self {
        Self {
            inner,
            epochs_started,
        }
    }
}

impl<O: 'static> DataLoader<O> for EpochCounting<O> {
    fn iter<'a>(&'a self) -> Box<dyn DataLoaderIterator<O> + 'a> {
        self.epochs_started.fetch_add(1, Ordering::Relaxed);
        self.inner.iter()
    }

    fn num_items(&self) -> usize {
        self.inner.num_items()
    }

    fn to_device(&self, device: &Device) -> Arc<dyn DataLoader<O>> {
        Arc::new(Self::new(
            self.inner.to_device(device),
            self.epochs_started.clone(),
        ))
    }

    fn slice(&self, start: usize, end: usize) -> Arc<dyn DataLoader<O>> {
        Arc::new(Self::new(
            self.inner.slice(start, end),
            self.epochs_started.clone(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{StereoBatcher, StereoItem};
    use burn::data::dataloader::DataLoaderBuilder;
    use hnet_model::training::TrainingBatch;
    use hnet_twin::dataset::simulate::simulate_dataset;
    use hnet_twin::simulator::scene::Modality;

    fn dataset(name: &str, seed: u64) -> Dataset {
        let root = std::env::temp_dir().join(format!("hnet-stream-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let twin = TwinConfig::new(Modality::Xray2, ImageSize::square(32));
        let backgrounds = Backgrounds::phantom(&twin.views);
        let names = ["phantom:+0/+0".to_string(), "phantom:+90/+0".to_string()];
        simulate_dataset(&twin, &backgrounds, &names, 4, seed, &root, &|_| {}).unwrap();
        Dataset::open(&root).unwrap()
    }

    /// Each pair of one epoch of `loader` (its view A's pixel sum and its force, in N, which
    /// is zero for masks-only pairs) and whether its force is a label, in a fixed order.
    fn epoch(loader: &dyn DataLoader<TrainingBatch>) -> Vec<([u32; 4], bool)> {
        let mut pairs = Vec::new();
        for batch in loader.iter() {
            let batch = batch.unwrap();
            let n = batch.len();
            let views = hnet_model::inference::host_values(batch.view_a).unwrap();
            let forces = hnet_model::inference::host_values(batch.force).unwrap();
            let known = hnet_model::inference::host_values(batch.force_known).unwrap();
            let per_view = views.len() / n;
            for ((v, f), k) in views
                .chunks_exact(per_view)
                .zip(forces.chunks_exact(3))
                .zip(known)
            {
                let sum: f32 = v.iter().sum();
                let bits = [
                    sum.to_bits(),
                    f[0].to_bits(),
                    f[1].to_bits(),
                    f[2].to_bits(),
                ];
                pairs.push((bits, k > 0.5));
            }
        }
        pairs.sort();
        pairs
    }

    fn loader(stream: TwinStream) -> EpochCounting<TrainingBatch> {
        let counter = stream.epochs_started();
        let size = ImageSize::square(16);
        let inner = DataLoaderBuilder::new(StereoBatcher { size })
            .batch_size(3)
            .shuffle(1)
            .set_device(Device::flex())
            .build(stream);
        EpochCounting::new(inner, counter)
    }

    #[test]
    fn every_epoch_is_fresh_and_a_resumed_run_continues_the_stream() {
        let data = dataset("fresh", 5);
        let config = TwinStreamConfig {
            pairs_per_epoch: 8,
            seed: 11,
            off_bench: Some(OffBenchConfig {
                fraction: 0.5,
                radiographs: Vec::new(),
                radiograph_fraction: 0.5,
                scenes: None,
                turned_views: false,
            }),
            imaging: None,
            random_patch_grid_fraction: 0.0,
        };
        // Detectors no X-ray system has are refused, naming the field.
        let mut foggy = config.clone();
        foggy.imaging = Some(ImagingConfig {
            fraction: 0.5,
            detectors: DetectorRanges {
                photons_per_pixel: [300.0, 3000.0],
                blur_px: [0.4, 2.0],
                scatter_fraction: [0.0, 1.5],
                display_gamma: [0.5, 1.6],
            },
        });
        let error = foggy.check().unwrap_err();
        assert!(
            format!("{error:#}").contains("scatter_fraction"),
            "{error:#}"
        );
        // Off-bench scenes that cannot be drawn are refused with the config's field named.
        let mut reversed = config.clone();
        if let Some(off) = &mut reversed.off_bench {
            off.scenes = Some(SceneSampling {
                length_mm: [60.0, 55.0],
                ..SceneSampling::varied()
            });
        }
        let error = reversed.check().unwrap_err();
        assert!(
            format!("{error:#}").starts_with("stream.off_bench.scenes: length_mm"),
            "{error:#}"
        );
        let size = ImageSize::square(16);
        let first = loader(TwinStream::new(&config, &data, size, 0).unwrap());
        let (one, two) = (epoch(&first), epoch(&first));
        assert_eq!(one.len(), 8);
        assert!(
            one.iter().all(|p| !two.contains(p)),
            "epoch 2 repeats epoch 1"
        );
        // Some pairs are off the bench (masks only), most of each kind at this fraction.
        let labelled = one.iter().chain(&two).filter(|p| p.1).count();
        assert!((3..=13).contains(&labelled), "{labelled} of 16 labelled");
        // A run resumed after one epoch trains on what the uninterrupted run's second was.
        let resumed = loader(TwinStream::new(&config, &data, size, 1).unwrap());
        assert_eq!(epoch(&resumed), two);

        // Turned views: each off-bench view is one of the square's symmetries of the same
        // pair unturned, its mask carried with it; bench pairs are left as they are.
        let mut turning = config.clone();
        if let Some(off) = &mut turning.off_bench {
            off.turned_views = true;
        }
        let plain = TwinStream::new(&config, &data, size, 0).unwrap();
        let turned = TwinStream::new(&turning, &data, size, 0).unwrap();
        let mut moved = 0;
        for index in 0..8 {
            let (p, t) = (plain.pair(index).unwrap(), turned.pair(index).unwrap());
            if p.force_known {
                assert_eq!((&p.view_a, &p.mask_b), (&t.view_a, &t.mask_b));
                continue;
            }
            let unturned = |view: &[u8], mask: &[u8]| LoadedPair {
                size,
                view_a: view.to_vec(),
                view_b: view.to_vec(),
                mask_a: mask.iter().map(|&m| f32::from(m) / 255.0).collect(),
                mask_b: mask.iter().map(|&m| f32::from(m) / 255.0).collect(),
            };
            let candidates = (0..8).map(|k| {
                let s = SquareSymmetry::nth(k);
                let c = StereoItem::new(
                    unturned(&p.view_b, &p.mask_b).with_symmetries([s; 2]),
                    hnet_units::TipForce::ZERO,
                    false,
                    String::new(),
                );
                (c.view_b, c.mask_b, s)
            });
            let (.., s) = candidates
                .into_iter()
                .find(|(v, m, _)| (v, m) == (&t.view_b, &t.mask_b))
                .expect("a turned view is a symmetry of the view, its mask with it");
            moved += usize::from(s != SquareSymmetry::IDENTITY);
        }
        assert!(moved > 0, "no off-bench view was turned");

        // The patch grid anywhere: the backgrounds move; a share outside [0, 1] is refused.
        let anywhere = TwinStreamConfig {
            random_patch_grid_fraction: 1.0,
            ..config.clone()
        };
        let shifted = TwinStream::new(&anywhere, &data, size, 0).unwrap();
        let moved = (0..8)
            .filter(|&i| plain.pair(i).unwrap().view_a != shifted.pair(i).unwrap().view_a)
            .count();
        assert!(moved >= 6, "{moved} of 8 pairs' backgrounds moved");
        let too_many = TwinStreamConfig {
            random_patch_grid_fraction: 1.5,
            ..config.clone()
        };
        let error = too_many.check().unwrap_err();
        assert!(
            format!("{error:#}").contains("random_patch_grid_fraction"),
            "{error:#}"
        );

        // The dataset's own seed would replay its val and test pairs: refused, naming it.
        let same = TwinStreamConfig { seed: 5, ..config };
        let error = TwinStream::new(&same, &data, size, 0).unwrap_err();
        assert!(format!("{error:#}").contains("stream.seed 5"), "{error:#}");
        std::fs::remove_dir_all(&data.root).ok();
    }
}
