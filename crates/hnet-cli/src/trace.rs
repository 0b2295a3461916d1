//! `hnet trace`: a trained model over every frame pair of a biplane DICOM cine, written as a
//! force trace CSV ([`hnet_dicom::trace_csv`], the page's format too). The trace holds no header
//! value besides the frame times, so no patient identifier.

use std::path::PathBuf;

use anyhow::{Context, bail};
use hnet_dicom::{TracePoint, trace_csv};
use hnet_twin::centreline::{CentrelineSettings, Mask, catheter_seen};
use hnet_twin::dataset::LoadedPair;

use crate::backend::BackendChoice;
use crate::cine::{grey_pair, open_cine};
use crate::data::StereoItem;
use crate::network::{load_weights, predict};
use crate::progress;

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
    let cine = open_cine(&args.dicom_a, &args.dicom_b)?;
    let pairs = &cine.pairing.pairs;
    let bar = progress::bar(pairs.len() as u64, "tracing");
    let mut trace = Vec::with_capacity(pairs.len());
    for chunk in pairs.chunks(args.batch_size.max(1)) {
        let items: Vec<StereoItem> = chunk
            .iter()
            .map(|pair| {
                let [a, b] = grey_pair(&cine, pair.frame);
                let empty = image::GrayImage::new(a.width(), a.height());
                let images = [a, b, empty.clone(), empty].map(image::DynamicImage::ImageLuma8);
                let loaded = LoadedPair::of_images(images, model.image_size);
                StereoItem::new(loaded, [0.0; 3], false, (pair.frame + 1).to_string())
            })
            .collect();
        let mut forces = Vec::with_capacity(chunk.len());
        let size = model.image_size;
        predict(
            &model,
            &items,
            args.batch_size,
            &device,
            |_, masks, force| {
                // A frame whose masks show no catheter in a view gets no force, and says why.
                let no_catheter = masks.as_ref().and_then(|[a, b]| {
                    let settings = CentrelineSettings::default();
                    [(a, "A"), (b, "B")].into_iter().find_map(|(mask, view)| {
                        catheter_seen(&Mask::soft(size.width, size.height, mask), view, &settings)
                            .err()
                    })
                });
                forces.push((force, no_catheter))
            },
        )?;
        for (pair, (force, no_catheter)) in chunk.iter().zip(forces) {
            let Some(f) = force else {
                bail!(
                    "weights file '{}' holds a `{}` network, which estimates no force",
                    args.weights.display(),
                    model.spec.name()
                );
            };
            trace.push(TracePoint {
                frame: pair.frame,
                time_s: pair.time_s,
                force_n: match no_catheter {
                    Some(why) => Err(hnet_units::with_causes(&why)),
                    None => Ok(f),
                },
            });
        }
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
    hnet_twin::files::write_atomically(&args.out, trace_csv(&trace).as_bytes())
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let without = trace.iter().filter(|p| p.force_n.is_err()).count();
    eprintln!(
        "force trace of {} frame pairs ({}) written to {}{}",
        pairs.len(),
        hnet_dicom::TRACE_ESTIMATOR,
        args.out.display(),
        if without > 0 {
            format!("; {without} frame(s) without a force: a view shows no catheter")
        } else {
            String::new()
        }
    );
    Ok(())
}
