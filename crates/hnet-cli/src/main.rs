//! `hnet`: the H-Net Studio command-line tool.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod allocator;
mod backend;
mod bench;
mod calibrate;
mod cine;
mod config;
mod contact_sheet;
mod data;
mod evaluation;
mod fine_tune;
mod import;
mod import_dicom;
mod info;
mod mismatch;
mod network;
mod no_catheter;
mod physics_check;
mod progress;
mod progress_renderer;
mod report;
mod run_dir;
mod simulate;
mod study;
mod trace;
mod training;

/// H-Net Studio: stereo catheter segmentation and 3D tip-force estimation.
#[derive(Parser, Debug)]
#[command(name = "hnet", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Describe the network of a configuration: parameter counts, input and output shapes.
    Info(info::InfoArgs),
    /// Generate a stereo dataset with the catheter digital twin.
    Simulate(simulate::SimulateArgs),
    /// Join the parts of a sharded simulation (`hnet simulate --shard K/N`) into one dataset.
    Merge(simulate::MergeArgs),
    /// Turn real recordings (two image folders, or a biplane DICOM cine, and a forces CSV) into
    /// a dataset.
    Import(import::ImportArgs),
    /// Train H-Net (or a baseline) on a dataset.
    Train(training::TrainArgs),
    /// Fine-tune weights on a few pairs the way the page does (encoders frozen, every fifth
    /// pair held back): the page's "Fine-tune on my pairs", natively.
    FineTune(fine_tune::FineTuneArgs),
    /// The paper's Tables I and II for a trained run on a dataset split.
    Eval(evaluation::EvalArgs),
    /// The paper's figures (SVG and PNG) for a trained run.
    Report(report::ReportArgs),
    /// Draw a dataset's first pairs (both views and masks) into one PNG.
    ContactSheet(contact_sheet::ContactSheetArgs),
    /// Measure throughput (see docs/benchmarks.md).
    Bench(bench::BenchArgs),
    /// Run a trained model over every frame pair of a biplane DICOM cine: a force trace CSV.
    Trace(trace::TraceArgs),
    /// Calibrate a catheter's stiffness from pairs labelled with a measured force, for the
    /// blind force estimate (`hnet eval --catheter FILE`).
    Calibrate(calibrate::CalibrateArgs),
    /// Study what a dataset allows (`hnet study ceiling`: the force recoverable from its geometry).
    Study(study::StudyArgs),
}

fn main() -> ExitCode {
    allocator::tune();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Merge(args) => simulate::merge(&args),
        // Image folders, or the two planes of a DICOM cine.
        Command::Import(args) if args.is_dicom() => import_dicom::run(&args),
        Command::Import(args) => import::run(&args),
        Command::Train(args) => training::run(&args),
        Command::FineTune(args) => fine_tune::run(&args),
        Command::Eval(args) => evaluation::run(&args),
        Command::Report(args) => report::run(&args),
        Command::ContactSheet(args) => contact_sheet::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Study(args) => study::run(&args),
        Command::Trace(args) => trace::run(&args),
        Command::Calibrate(args) => calibrate::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            // Each cause once: a wrapper that already words its cause (a weights file's name and
            // its problem) is not followed by the cause again.
            eprintln!("error: {}", hnet_units::with_causes(error.as_ref()));
            ExitCode::FAILURE
        }
    }
}

/// The command as typed, its program named `hnet`: what provenance records (weights files, run
/// folders) keep, without the install path of the machine that ran it.
pub(crate) fn command_line() -> String {
    std::iter::once("hnet".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ")
}
