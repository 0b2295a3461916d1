//! `hnet bench`: throughput measurements recorded in docs/benchmarks.md.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use hnet_twin::dataset::simulate::simulate_dataset;
use hnet_twin::simulator::scene::{Modality, TwinConfig};
use hnet_units::ImageSize;
use serde::Serialize;

use crate::backend::BackendChoice;
use crate::simulate::{backgrounds, parse_modality};

mod layers;

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchCommand,
}

#[derive(clap::Subcommand, Debug)]
enum BenchCommand {
    /// Stereo samples per second of `hnet simulate`, PNG writing included.
    Simulate(SimulateBench),
    /// H-Net training step time (batch of stereo pairs) and inference latency (one pair).
    Model(ModelBench),
    /// Forward and both backward passes of each H-Net convolution, layer by layer.
    Layers(layers::LayersBench),
}

/// Whose convolution kernels flex runs (`--kernels`): an A/B switch for the benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernels {
    /// The project's (crates/hnet-conv), as every other command uses.
    Project,
    /// The project's, with Winograd's F(2x2, 3x3) only, never F(4x4, 3x3).
    Winograd2x2,
    /// The project's, with stride-1 3x3 convolutions computed directly instead of by
    /// Winograd's kernel.
    Direct,
    /// Burn flex's own convolutions.
    Burn,
}

impl Kernels {
    /// Makes the whole process use these kernels.
    pub fn select(self) {
        hnet_conv::use_project_kernels(self != Kernels::Burn);
        hnet_conv::use_winograd(matches!(self, Kernels::Project | Kernels::Winograd2x2));
        hnet_conv::use_large_winograd_tiles(self == Kernels::Project);
    }
}

#[derive(clap::Args, Debug)]
struct ModelBench {
    /// Backends to measure.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "flex")]
    backend: Vec<BackendChoice>,
    /// Whose convolution kernels flex runs.
    #[arg(long, value_enum, default_value = "project")]
    kernels: Kernels,
    /// Image side in pixels [default: 64, or the size `--weights` records].
    #[arg(long)]
    size: Option<usize>,
    /// Times the network in this H-Net weights file (e.g. `assets/hnet-cpu.bpk`), its settings
    /// (position channels, force scale) and weights included: the very network
    /// `bench/onnx_hnet.py` exports for ONNX Runtime. At another `--size`, the same architecture
    /// freshly initialised (the time does not depend on the weights' values). Without it, a
    /// freshly initialised default H-Net.
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Pairs per training batch.
    #[arg(long, default_value_t = 32)]
    batch: usize,
    /// Timed training steps (after one warm-up step); 0 times inference only.
    #[arg(long, default_value_t = 5)]
    steps: usize,
    /// Timed inferences (after one warm-up).
    #[arg(long, default_value_t = 20)]
    runs: usize,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct ModelResult {
    backend: &'static str,
    kernels: Kernels,
    params: usize,
    size: usize,
    batch: usize,
    threads: usize,
    /// Seconds per training step; `None` with `--steps 0`.
    train_step_s: Option<f64>,
    infer_pair_s: f64,
}

fn model(args: &ModelBench) -> anyhow::Result<()> {
    use burn::module::Module;
    use burn::optim::{GradientsParams, RmsPropConfig};
    use burn::tensor::{Distribution, Tensor};
    use hnet_model::predictor::PairInput;
    use hnet_model::{HNetConfig, HNetLossConfig};

    args.kernels.select();
    let mut results = Vec::new();
    for backend in &args.backend {
        let device = backend.device()?;
        let loaded = args
            .weights
            .as_deref()
            .map(|path| crate::network::load_weights(path, None, &device))
            .transpose()?;
        let config = match &loaded {
            Some(predictor) => match &predictor.spec {
                hnet_model::architectures::ModelSpec::Hnet(config) => config.clone(),
                other => anyhow::bail!(
                    "weights file '{}' holds a `{}` network: `hnet bench model` times H-Net",
                    args.weights.as_deref().unwrap_or(Path::new("")).display(),
                    other.name()
                ),
            },
            None => HNetConfig::new().with_image_size(ImageSize::square(args.size.unwrap_or(64))),
        };
        let config = match args.size {
            Some(side) => config.with_image_size(ImageSize::square(side)),
            None => config,
        };
        let size = config.image_size;
        // The file's own network, when it is the size timed.
        let loaded = loaded.filter(|predictor| predictor.image_size == size);
        let train_device = device.clone().autodiff();
        let mut net = config.init(&train_device)?;
        let params = net.num_params();
        let train_step_s = if args.steps > 0 {
            let loss = HNetLossConfig::new().init();
            let mut optimizer = RmsPropConfig::new()
                .with_alpha(0.9)
                .with_momentum(0.0)
                .with_epsilon(1e-7)
                .init();
            let shape = [args.batch, 3, size.height, size.width];
            let mask = [args.batch, 1, size.height, size.width];
            let a = Tensor::random(shape, Distribution::Default, &train_device);
            let b = Tensor::random(shape, Distribution::Default, &train_device);
            let ma = Tensor::random(mask, Distribution::Bernoulli(0.1), &train_device);
            let mb = Tensor::random(mask, Distribution::Bernoulli(0.1), &train_device);
            let f = Tensor::random(
                [args.batch, 3],
                Distribution::Uniform(-0.4, 0.4),
                &train_device,
            );
            let mut step = |net: hnet_model::HNet| {
                let out = net.forward(a.clone(), b.clone());
                let terms = loss.forward(&out, ma.clone(), mb.clone(), f.clone());
                let grads = GradientsParams::from_grads(terms.total.backward(), &net);
                let net = optimizer.step(1e-4, net, grads);
                // Wait for the device so that the time is the step's.
                let _ = terms.total.into_scalar::<f32>();
                net
            };
            net = step(net);
            let start = Instant::now();
            for _ in 0..args.steps {
                net = step(net);
            }
            Some(start.elapsed().as_secs_f64() / args.steps as f64)
        } else {
            None
        };

        // One mid-grey pair, from bytes to the masks and force in host memory.
        let pixels = vec![128u8; size.pixels() * 3];
        let infer_pair_s = match &loaded {
            Some(predictor) => {
                let pair = [PairInput {
                    view_a: &pixels,
                    view_b: &pixels,
                    masks: None,
                }];
                time_runs(args.runs, || predictor.predict(&pair, &device).map(drop))?
            }
            None => {
                let net = net.valid();
                let pair = [hnet_model::inference::StereoPair {
                    view_a: &pixels,
                    view_b: &pixels,
                }];
                let single = hnet_model::mask_averaging::MaskAveraging::Single;
                time_runs(args.runs, || {
                    net.predict(&pair, size, &device, single).map(drop)
                })?
            }
        };
        results.push(ModelResult {
            backend: backend.name(),
            kernels: args.kernels,
            params,
            size: size.width,
            batch: args.batch,
            threads: rayon::current_num_threads(),
            train_step_s,
            infer_pair_s,
        });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        for r in &results {
            let step = r
                .train_step_s
                .map_or_else(|| "not timed".to_string(), |s| format!("{:.1} ms", s * 1e3));
            println!(
                "{} ({:?} kernels): H-Net ({} parameters) at {}x{}: training step (batch {}) {step}, inference per stereo pair {:.1} ms, {} threads",
                r.backend,
                r.kernels,
                r.params,
                r.size,
                r.size,
                r.batch,
                r.infer_pair_s * 1e3,
                r.threads
            );
        }
    }
    Ok(())
}

/// Mean seconds per call of `run` over `runs` calls, after one warm-up call.
fn time_runs<E: std::error::Error + Send + Sync + 'static>(
    runs: usize,
    mut run: impl FnMut() -> Result<(), E>,
) -> anyhow::Result<f64> {
    run()?;
    let start = Instant::now();
    for _ in 0..runs {
        run()?;
    }
    Ok(start.elapsed().as_secs_f64() / runs.max(1) as f64)
}

#[derive(clap::Args, Debug)]
struct SimulateBench {
    /// Image look.
    #[arg(long, value_parser = parse_modality, default_value = "xray2")]
    modality: Modality,
    /// Stereo pairs to generate.
    #[arg(long, default_value_t = 2000)]
    samples: usize,
    /// Image side in pixels.
    #[arg(long, default_value_t = 224)]
    size: usize,
    /// Scratch folder (removed afterwards); a fresh temporary folder by default.
    #[arg(long)]
    scratch: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct SimulateResult {
    modality: &'static str,
    size: usize,
    samples: usize,
    threads: usize,
    seconds: f64,
    samples_per_second: f64,
    bytes_written: u64,
}

fn folder_size(path: &std::path::Path) -> u64 {
    std::fs::read_dir(path)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| {
                    let p = e.path();
                    if p.is_dir() {
                        folder_size(&p)
                    } else {
                        e.metadata().map(|m| m.len()).unwrap_or(0)
                    }
                })
                .sum()
        })
        .unwrap_or(0)
}

fn simulate(args: &SimulateBench) -> anyhow::Result<()> {
    let config = TwinConfig::new(args.modality, ImageSize::square(args.size));
    let (backgrounds, names) = backgrounds(&config, &[])?;
    let scratch = args.scratch.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("hnet-bench-simulate-{}", std::process::id()))
    });
    if scratch.exists() {
        std::fs::remove_dir_all(&scratch)
            .with_context(|| format!("cannot clear scratch folder '{}'", scratch.display()))?;
    }
    let start = Instant::now();
    simulate_dataset(
        &config,
        &backgrounds,
        &names,
        args.samples,
        1,
        &scratch,
        &|_| {},
    )?;
    let seconds = start.elapsed().as_secs_f64();
    let result = SimulateResult {
        modality: args.modality.name(),
        size: args.size,
        samples: args.samples,
        threads: rayon::current_num_threads(),
        seconds,
        samples_per_second: args.samples as f64 / seconds,
        bytes_written: folder_size(&scratch),
    };
    std::fs::remove_dir_all(&scratch).ok();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        println!(
            "simulate {} at {}x{}: {} stereo pairs in {:.2} s on {} threads = {:.0} pairs/s ({:.1} MB written)",
            result.modality,
            result.size,
            result.size,
            result.samples,
            result.seconds,
            result.threads,
            result.samples_per_second,
            result.bytes_written as f64 / 1e6
        );
    }
    Ok(())
}

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    match &args.what {
        BenchCommand::Simulate(a) => simulate(a),
        BenchCommand::Model(a) => model(a),
        BenchCommand::Layers(a) => layers::run(a),
    }
}
