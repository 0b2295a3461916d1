//! `hnet bench`: throughput measurements recorded in docs/benchmarks.md.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use hnet_twin::scene::{Modality, TwinConfig};
use hnet_twin::simulate::simulate_dataset;
use serde::Serialize;

use crate::simulate::{backgrounds, parse_modality};

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchCommand,
}

#[derive(clap::Subcommand, Debug)]
enum BenchCommand {
    /// Stereo samples per second of `hnet simulate`, PNG writing included.
    Simulate(SimulateBench),
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
    let config = TwinConfig::new(args.modality, args.size);
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
    }
}
