//! `hnet simulate`: a stereo dataset from the catheter digital twin.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use hnet_twin::dataset::import::is_image_file;
use hnet_twin::dataset::shard::{Shard, merge_shards};
use hnet_twin::dataset::simulate::{
    OFF_BENCH_VIEWS, Part, simulate_dataset_part, simulate_off_bench_dataset,
};
use hnet_twin::simulator::off_bench::OffBench;
use hnet_twin::simulator::raster::GreyImage;
use hnet_twin::simulator::render::XRayDetector;
use hnet_twin::simulator::scene::{
    Backgrounds, MaskRecipe, Modality, PAPER_BENCH, SceneSampling, TwinConfig,
};
use hnet_twin::simulator::synthetic_xray::BackgroundSource;

use crate::progress;
use hnet_units::ImageSize;

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Image look: `rgb` (bench cameras), `xray1` (bright patches) or `xray2` (mixed patches).
    #[arg(long, value_parser = parse_modality, default_value = "xray2")]
    pub modality: Modality,
    /// Number of stereo pairs.
    #[arg(long)]
    pub samples: usize,
    /// Side of the square images in pixels.
    #[arg(long, default_value_t = 224)]
    pub size: usize,
    /// Seed of every random choice: the same seed gives byte-identical output.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output folder (created; an interrupted generation there is resumed).
    #[arg(long)]
    pub out: PathBuf,
    /// Chest radiographs (PNG/JPEG files, or folders of them) to cut X-ray backgrounds from;
    /// the built-in thorax phantom when none is given.
    #[arg(long = "background")]
    pub backgrounds: Vec<PathBuf>,
    /// How masks are made: `geometry` (exact), `otsu`, a grey level 0-255 to threshold at, or
    /// `cutout` (the bench photograph thresholded against the empty bench, the paper's way).
    /// Default: `geometry`, `cutout` for `--scenes paper-bench`.
    #[arg(long, value_parser = parse_mask)]
    pub mask: Option<MaskRecipe>,
    /// How scenes are drawn: `bench` (the twin's bench seen by the C-arm: one catheter on a
    /// fixed base, a random tip force), `varied` (random catheters and base poses too; see
    /// docs/twin.md), `paper-bench` (the paper's bench as its cameras saw it: close up, the tip
    /// pressed against an actuated sensor plate, the X-ray sets made the paper's way) or
    /// `off-bench` (varied scenes seen from random C-arm angles within the page's ranges, on the
    /// phantom rendered from there, or on the `--background` radiographs when given).
    #[arg(long, default_value = "bench", value_parser = parse_scenes)]
    pub scenes: Scenes,
    /// Draw catheters and poses from this JSON file instead (every field of a scene sampling, as
    /// a training config's `stream.off_bench.scenes` takes them; docs/twin.md); with `--scenes
    /// off-bench`, those scenes seen off the bench.
    #[arg(long)]
    pub scene_sampling: Option<PathBuf>,
    /// The X-ray detector from this JSON file (`photons_per_pixel`, `blur_px`,
    /// `scatter_fraction`, `display_gamma`; fields left out keep the twin's defaults, docs/twin.md)
    /// instead of the twin's: low-dose noise, blur, scatter and veiling glare, a display curve.
    #[arg(long, value_parser = read_detector)]
    pub detector: Option<XRayDetector>,
    /// Start each X-ray background's grid of shuffled patches at a random place, so that the
    /// patches' edges fall anywhere rather than every quarter of the view (the paper's recipe
    /// puts them there; a network trained on it learns to expect them there).
    #[arg(long)]
    pub random_patch_grid: bool,
    /// Write only part K of N of the pairs (`K/N`, K from 0: a Slurm array task's or a
    /// Kubernetes completion index), each part on its own machine; `hnet merge` joins the N
    /// parts into the dataset one run would write, byte for byte.
    #[arg(long, value_parser = Shard::parse)]
    pub shard: Option<Shard>,
}

/// `hnet merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The parts (`hnet simulate --shard K/N` folders), in any order.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// The dataset folder to write.
    #[arg(long)]
    out: PathBuf,
}

/// Joins a sharded simulation's parts into one dataset.
pub fn merge(args: &MergeArgs) -> anyhow::Result<()> {
    let report = merge_shards(&args.parts, &args.out)?;
    eprintln!(
        "{} stereo pairs from {} parts in {}",
        report.samples,
        report.parts,
        args.out.display()
    );
    Ok(())
}

/// The X-ray detector in the JSON file at `path`, checked.
fn read_detector(path: &str) -> Result<XRayDetector, String> {
    let bytes =
        std::fs::read(path).map_err(|e| format!("cannot read detector file '{path}': {e}"))?;
    let detector: XRayDetector = serde_json::from_slice(&bytes)
        .map_err(|e| format!("'{path}' is not an X-ray detector: {e}"))?;
    detector.check().map_err(|why| format!("'{path}': {why}"))?;
    Ok(detector)
}

/// The scene sampling in the JSON file at `path`, checked.
fn read_scene_sampling(path: &Path) -> anyhow::Result<SceneSampling> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read scene sampling '{}'", path.display()))?;
    let sampling: SceneSampling = serde_json::from_slice(&bytes)
        .with_context(|| format!("'{}' is not a scene sampling", path.display()))?;
    sampling
        .check()
        .map_err(|why| anyhow::anyhow!("'{}': {why}", path.display()))?;
    Ok(sampling)
}

/// What `--scenes` asks for.
#[derive(Debug, Clone)]
pub enum Scenes {
    /// A preset of scene sampling, the twin's default views.
    Preset(Box<SceneSampling>),
    /// Off-bench pairs ([`OffBench`]).
    OffBench,
}

fn parse_scenes(text: &str) -> Result<Scenes, String> {
    if text == OFF_BENCH_VIEWS {
        return Ok(Scenes::OffBench);
    }
    SceneSampling::preset(text)
        .map(|s| Scenes::Preset(Box::new(s)))
        .ok_or_else(|| {
            format!(
                "`{text}` is not {} or {OFF_BENCH_VIEWS}",
                SceneSampling::PRESETS.join(", ")
            )
        })
}

pub fn parse_modality(text: &str) -> Result<Modality, String> {
    Modality::parse(text).ok_or_else(|| format!("`{text}` is not rgb, xray1 or xray2"))
}

fn parse_mask(text: &str) -> Result<MaskRecipe, String> {
    match text {
        "geometry" => Ok(MaskRecipe::Geometry),
        "otsu" => Ok(MaskRecipe::Otsu),
        "cutout" => Ok(MaskRecipe::Cutout),
        level => level
            .parse::<u8>()
            .map(MaskRecipe::Threshold)
            .map_err(|_| format!("`{text}` is not geometry, otsu or a grey level 0-255")),
    }
}

/// The image files named by `paths` (folders expand to the images in them, sorted).
pub fn background_files(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("cannot list background folder '{}'", path.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| is_image_file(p))
                .collect();
            found.sort();
            if found.is_empty() {
                bail!("background folder '{}' holds no images", path.display());
            }
            files.extend(found);
        } else if !path.exists() {
            // A config's relative path is read from where hnet runs, not from the config's
            // folder: say so, since that is the usual cause.
            let from = if path.is_relative() {
                std::env::current_dir()
                    .map(|cwd| {
                        format!(
                            " (a relative path is read from the working directory, {})",
                            cwd.display()
                        )
                    })
                    .unwrap_or_default()
            } else {
                String::new()
            };
            bail!("background '{}' does not exist{from}", path.display());
        } else {
            files.push(path.clone());
        }
    }
    Ok(files)
}

/// Loads a chest radiograph as a background source.
pub fn load_radiograph(path: &Path) -> anyhow::Result<BackgroundSource> {
    let image = image::open(path)
        .with_context(|| format!("background '{}' is not a readable image", path.display()))?
        .to_luma8();
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string());
    Ok(BackgroundSource::chest_radiograph(
        name,
        GreyImage::from_u8(
            image.width() as usize,
            image.height() as usize,
            image.as_raw(),
        ),
    ))
}

/// The backgrounds of a run and their names (recorded in the dataset header).
pub fn backgrounds(
    config: &TwinConfig,
    paths: &[PathBuf],
) -> anyhow::Result<(Backgrounds, Vec<String>)> {
    if !config.modality.is_xray() {
        return Ok((Backgrounds::default(), Vec::new()));
    }
    if paths.is_empty() {
        let backgrounds = Backgrounds::phantom(&config.views);
        let names = backgrounds
            .per_view
            .iter()
            .flatten()
            .map(|s| s.name.clone())
            .collect();
        return Ok((backgrounds, names));
    }
    let (sources, names) = radiographs(paths)?;
    Ok((Backgrounds::files(sources), names))
}

/// The chest radiographs named by `paths` (files, or folders of images) and their names.
pub fn radiographs(paths: &[PathBuf]) -> anyhow::Result<(Vec<BackgroundSource>, Vec<String>)> {
    let sources = background_files(paths)?
        .iter()
        .map(|p| load_radiograph(p))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let names = sources.iter().map(|s| s.name.clone()).collect();
    Ok((sources, names))
}

pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    if args.samples == 0 {
        bail!("--samples must be at least 1");
    }
    if args.size < 16 {
        bail!("--size must be at least 16 pixels");
    }
    let paper_bench = matches!(&args.scenes, Scenes::Preset(s) if s.plate.is_some());
    let mut config = if paper_bench {
        TwinConfig::paper_bench(args.modality, ImageSize::square(args.size))
    } else {
        TwinConfig::new(args.modality, ImageSize::square(args.size))
    };
    if let Some(mask) = args.mask {
        config.mask = mask;
    }
    if let Some(detector) = args.detector {
        if !config.modality.is_xray() {
            bail!("--detector is for the X-ray modalities (xray1, xray2)");
        }
        detector
            .check()
            .map_err(|why| anyhow::anyhow!("--detector: {why}"))?;
        config.detector = detector;
    }
    if args.random_patch_grid {
        if !config.modality.is_xray() {
            bail!("--random-patch-grid is for the X-ray modalities (xray1, xray2)");
        }
        config.patches.random_grid_offset = true;
    }
    let sampling = args
        .scene_sampling
        .as_deref()
        .map(read_scene_sampling)
        .transpose()?;
    let part = Part {
        samples: args.samples,
        seed: args.seed,
        shard: args.shard.unwrap_or(Shard::WHOLE),
    };
    let range = part.shard.range(args.samples);
    let bar = progress::bar(range.end - range.start, "simulating");
    let progress = |done: usize| bar.set_position(done as u64);
    let start = Instant::now();
    let report = match &args.scenes {
        Scenes::Preset(scenes) => {
            config.scene = sampling.unwrap_or_else(|| (**scenes).clone());
            if config.scene.plate.is_some() && !paper_bench {
                bail!(
                    "a scene sampling with a plate needs the paper's bench views: add \
                     --scenes {PAPER_BENCH}"
                );
            }
            let (backgrounds, names) = backgrounds(&config, &args.backgrounds)?;
            simulate_dataset_part(&config, &backgrounds, &names, part, &args.out, &progress)?
        }
        Scenes::OffBench => {
            if !config.modality.is_xray() {
                bail!("--scenes {OFF_BENCH_VIEWS} is for the X-ray modalities");
            }
            // Radiographs when given (every pair on one), else the phantom from each view.
            let (radiographs, names) = if args.backgrounds.is_empty() {
                (Vec::new(), vec!["phantom:off-bench".to_string()])
            } else {
                radiographs(&args.backgrounds)?
            };
            let off_bench = OffBench::new(config.clone(), radiographs, 1.0);
            let off_bench = match sampling {
                Some(scenes) => off_bench.with_scenes(scenes),
                None => off_bench,
            };
            simulate_off_bench_dataset(&off_bench, &names, part, &args.out, &progress)?
        }
    };
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    eprintln!(
        "{} stereo pairs in {} ({} generated in {seconds:.1} s{}, {} already there)",
        args.samples,
        args.out.display(),
        report.generated,
        if report.generated > 0 {
            format!(", {:.0}/s", report.generated as f64 / seconds)
        } else {
            String::new()
        },
        report.resumed
    );
    if report.dropped_draws > 0 {
        eprintln!(
            "{} scene draws dropped: their rod or contact could not be solved (or the force was \
             beyond the sensor's range); each of those pairs was drawn again",
            report.dropped_draws
        );
    }
    Ok(())
}
