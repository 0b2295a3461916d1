//! `hnet import`: real recordings into the dataset format.

use std::path::PathBuf;

use anyhow::bail;
use hnet_twin::import::{ImportOptions, MaskThreshold, import_recordings};

use crate::progress;

#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// Folder of view A images.
    #[arg(long)]
    view_a: PathBuf,
    /// Folder of view B images (same file names as view A).
    #[arg(long)]
    view_b: PathBuf,
    /// CSV with a header: an image column (`image`, `file`, `frame` or `name`) and `fx,fy,fz`
    /// in newtons.
    #[arg(long)]
    forces: PathBuf,
    /// Output dataset folder.
    #[arg(long)]
    out: PathBuf,
    /// Mask threshold: a grey level 0-255 (the catheter is at or below it) or `otsu`.
    #[arg(long, default_value = "otsu", value_parser = parse_threshold)]
    threshold: MaskThreshold,
    /// The catheter is brighter than its background (masks take the pixels above the level).
    #[arg(long)]
    bright_catheter: bool,
    /// Resize every image to SIZE x SIZE pixels (otherwise all must have the same size).
    #[arg(long)]
    size: Option<usize>,
    /// Report bad rows and images and go on instead of stopping at the first one.
    #[arg(long)]
    skip_bad: bool,
    /// Seed of the 80/10/10 train/val/test split.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

fn parse_threshold(text: &str) -> Result<MaskThreshold, String> {
    if text == "otsu" {
        return Ok(MaskThreshold::Otsu);
    }
    text.parse::<u8>()
        .map(MaskThreshold::Level)
        .map_err(|_| format!("`{text}` is neither a grey level 0-255 nor `otsu`"))
}

pub fn run(args: &ImportArgs) -> anyhow::Result<()> {
    if args.size == Some(0) {
        bail!("--size must be at least 1");
    }
    let options = ImportOptions {
        view_a: args.view_a.clone(),
        view_b: args.view_b.clone(),
        forces: args.forces.clone(),
        out: args.out.clone(),
        threshold: args.threshold,
        bright_catheter: args.bright_catheter,
        size: args.size,
        skip_bad: args.skip_bad,
        seed: args.seed,
    };
    let bar = progress::bar(0, "importing");
    let report = import_recordings(&options, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let skipped = report.skipped.len();
    for problem in report.skipped {
        // anyhow's alternate form prints the problem with its causes, as `main` does.
        eprintln!("skipped: {:#}", anyhow::Error::from(problem));
    }
    eprintln!(
        "{} stereo pairs imported into {}{}",
        report.imported,
        args.out.display(),
        if skipped == 0 {
            String::new()
        } else {
            format!(", {skipped} rows skipped")
        }
    );
    Ok(())
}
