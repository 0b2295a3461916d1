//! `hnet`: the H-Net Studio command-line tool.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod info;

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
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
