//! `hnet trace`: a trained model over every frame pair of a biplane DICOM cine, written as a
//! force trace CSV (`frame,time_s,fx_n,fy_n,fz_n,magnitude_n`; frames from 1, time in seconds
//! after plane A's first frame, empty when the headers give no frame time). The trace holds no
//! header value besides the frame times, so no patient identifier.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, bail};
use hnet_model::inference::force_magnitude;
use hnet_twin::dataset::LoadedPair;

use crate::backend::BackendChoice;
use crate::cine::BiplaneCine;
use crate::data::StereoItem;
use crate::evaluation::{load_weights, predict};
use crate::progress;

/// The trace's header line.
pub const TRACE_COLUMNS: &str = "frame,time_s,fx_n,fy_n,fz_n,magnitude_n";

#[derive(clap::Args, Debug)]
pub struct TraceArgs {
    /// A weights file (`model.bpk` of a run, or the page's bundled weights) of a network with a
    /// force head.
    #[arg(long)]
    weights: PathBuf,
    /// Plane A of the biplane cine: a DICOM file, or a folder of its files.
    #[arg(long)]
    dicom_a: PathBuf,
    /// Plane B, frame for frame with plane A.
    #[arg(long)]
    dicom_b: PathBuf,
    /// The force trace CSV to write.
    #[arg(long)]
    out: PathBuf,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// Frame pairs per batch.
    #[arg(long, default_value_t = 16)]
    batch_size: usize,
}

pub fn run(args: &TraceArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let model = load_weights(&args.weights, None, &device)?;
    let cine = BiplaneCine::open(&args.dicom_a, &args.dicom_b)?;
    let pairs = &cine.pairing.pairs;
    let bar = progress::bar(pairs.len() as u64, "tracing");
    let mut csv = format!("{TRACE_COLUMNS}\n");
    for chunk in pairs.chunks(args.batch_size.max(1)) {
        let items: Vec<StereoItem> = chunk
            .iter()
            .map(|pair| {
                let [a, b] = cine.grey_pair(pair.frame);
                let empty = image::GrayImage::new(a.width(), a.height());
                let images = [a, b, empty.clone(), empty].map(image::DynamicImage::ImageLuma8);
                let loaded = LoadedPair::of_images(images, model.image_size);
                StereoItem::new(loaded, [0.0; 3], false, (pair.frame + 1).to_string())
            })
            .collect();
        let mut forces = Vec::with_capacity(chunk.len());
        predict(&model, &items, args.batch_size, &device, |_, _, force| {
            forces.push(force)
        })?;
        for (pair, force) in chunk.iter().zip(forces) {
            let Some(f) = force else {
                bail!(
                    "weights file '{}' holds a `{}` network, which estimates no force",
                    args.weights.display(),
                    model.spec.name()
                );
            };
            let magnitude = force_magnitude(f);
            let time = pair.time_s.map(|t| format!("{t:.4}")).unwrap_or_default();
            writeln!(
                csv,
                "{},{time},{},{},{},{magnitude}",
                pair.frame + 1,
                f[0],
                f[1],
                f[2]
            )
            .expect("writing to a string");
        }
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
    hnet_twin::files::write_atomically(&args.out, csv.as_bytes())
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    eprintln!(
        "force trace of {} frame pairs written to {}",
        pairs.len(),
        args.out.display()
    );
    Ok(())
}
