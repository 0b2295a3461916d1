//! `hnet calibrate`: a catheter's bending stiffness from a few pairs labelled with a measured tip
//! force (a bench with a force sensor, as the paper had), for the blind force estimate.
//!
//! Pairs whose force label was copied from a model's estimate are left out (not a measurement).
//! Each pair's catheter is read blind from its label masks (or, with `--weights`, a network's)
//! ([`PhysicsSetup::blind`]: the catalogue catheter, the base fitted from its nominal pose, the
//! C-arms from the pair's recorded geometry), and one stiffness scale is fitted to the measured forces
//! ([`hnet_twin::reconstruction::catalogue::calibrate_stiffness`]; why one scale is all images leave open is in
//! that module). The result is a catheter file that `hnet eval --catheter` reads.

use std::path::PathBuf;

use anyhow::Context;
use hnet_twin::dataset::Dataset;
use hnet_twin::dataset::files::write_atomically;
use hnet_twin::dataset::simulate::{blind_cameras, nominal_base, read_pair_carms};
use hnet_twin::reconstruction::catalogue::{
    BENCH_CATHETER, CatalogueCatheter, calibrate_stiffness,
};
use hnet_twin::reconstruction::centreline::Mask;
use hnet_twin::reconstruction::physics_force::{PhysicsSetup, physics_estimate};
use rayon::prelude::*;

use crate::backend::BackendChoice;
use crate::data::StereoItem;
use crate::evaluation::parse_split;
use crate::network::{load_weights, parse_mask_averaging, predict, read_views_as_recorded};
use hnet_twin::dataset::Split;
use hnet_units::mask::MaskAveraging;
use hnet_units::{ImageSize, TipForce};

#[derive(clap::Args, Debug)]
pub struct CalibrateArgs {
    /// Dataset of pairs labelled with a measured tip force, with label masks and each pair's
    /// C-arm geometry (simulated, or imported from a DICOM cine).
    #[arg(long)]
    data: PathBuf,
    /// The catheter to calibrate: a catalogue name or a catheter file.
    #[arg(long, default_value = BENCH_CATHETER)]
    catheter: String,
    /// Which split's pairs (all of them when left out).
    #[arg(long, value_parser = parse_split)]
    split: Option<Split>,
    /// Use only the first this many pairs (in the manifest's order).
    #[arg(long)]
    pairs: Option<usize>,
    /// The calibrated catheter file to write (JSON).
    #[arg(long)]
    out: PathBuf,
    /// Read each pair's catheter from these weights' masks instead of its label masks (for
    /// pairs labelled with a force only).
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Where to compute the masks (with `--weights`).
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// With `--weights`: how each view is read for its mask (`single` or `mirrored`, as `hnet
    /// eval`); by default as the weights' calibration was measured.
    #[arg(long, requires = "weights", value_parser = parse_mask_averaging)]
    mask_averaging: Option<MaskAveraging>,
}

/// A pair's measured force and its blind estimate, N.
type ForcePair = (TipForce, TipForce);

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let catheter = CatalogueCatheter::find(&args.catheter)?;
    let dataset = Dataset::open(&args.data)?;
    // A model's estimate is no measurement: calibrating on it would fit the model to itself.
    let estimates = dataset
        .rows
        .iter()
        .filter(|row| row.label_origin().is_ok_and(|o| o.is_estimate()))
        .count();
    let rows: Vec<_> = dataset
        .rows
        .iter()
        .filter(|row| args.split.is_none_or(|split| row.split == split))
        .filter(|row| !row.label_origin().is_ok_and(|o| o.is_estimate()))
        .take(args.pairs.unwrap_or(usize::MAX))
        .collect();
    if estimates > 0 {
        eprintln!(
            "{estimates} pair(s) of {} are left out: their force labels were copied from a \
             model's estimate, not measured",
            args.data.display()
        );
    }
    anyhow::ensure!(
        !rows.is_empty(),
        "{}: no pairs to calibrate on{}",
        args.data.display(),
        if estimates > 0 {
            " (only labels copied from a model's estimate, which are not measurements)"
        } else {
            ""
        }
    );
    let base = nominal_base(&dataset);
    // Each pair's masks (view A, view B) and their size: the labels, or the network's.
    let (size, masks): (ImageSize, Vec<[Vec<f32>; 2]>) = match &args.weights {
        None => {
            let loaded = rows
                .par_iter()
                .map(|row| dataset.load_pair(row, None).map(|p| [p.mask_a, p.mask_b]))
                .collect::<Result<_, _>>()?;
            (dataset.header.image_size, loaded)
        }
        Some(weights) => {
            let device = args.backend.device()?;
            let mut model = load_weights(weights, None, &device)?;
            read_views_as_recorded(&mut model, args.mask_averaging, weights)?;
            anyhow::ensure!(
                model.spec.heads().0,
                "weights file '{}' holds a `{}` network, which gives no masks",
                weights.display(),
                model.spec.name()
            );
            let items = rows
                .iter()
                .map(|row| {
                    let pair = dataset.load_pair(row, Some(model.image_size))?;
                    Ok(StereoItem::new(pair, row.force_n, true, row.id.clone()))
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            let mut masks = Vec::with_capacity(items.len());
            predict(&model, &items, 16, &device, |_, m, _| {
                masks.push(m.unwrap_or_default())
            })?;
            (model.image_size, masks)
        }
    };
    // Per pair: (measured force, blind estimate) in newtons, or why it gave none.
    let read: Vec<Result<ForcePair, String>> = rows
        .par_iter()
        .zip(&masks)
        .map(|(row, [a, b])| {
            let carms = read_pair_carms(&dataset, &row.id).map_err(|e| e.to_string())?;
            let setup = PhysicsSetup::blind(blind_cameras(&carms, size), &catheter, &base);
            let masks = [a, b].map(|m| Mask::soft(size.width, size.height, m));
            let estimate =
                physics_estimate(masks, &setup).map_err(|e| format!("pair {}: {e}", row.id))?;
            Ok((row.force_n, estimate.fit.force_n))
        })
        .collect();
    let mut pairs = Vec::new();
    for result in read {
        match result {
            Ok(pair) => pairs.push(pair),
            Err(why) => eprintln!("left out: {why}"),
        }
    }
    let calibrated = calibrate_stiffness(&catheter, &pairs).with_context(|| {
        format!(
            "cannot calibrate catheter `{}` from {}",
            catheter.name,
            args.data.display()
        )
    })?;
    let json = serde_json::to_vec_pretty(&calibrated)?;
    write_atomically(&args.out, &json)
        .with_context(|| format!("cannot write '{}'", args.out.display()))?;
    let c = calibrated
        .calibration
        .expect("a calibrated catheter records its calibration");
    println!(
        "catheter `{}`: stiffness {:.3} mN·m² (nominal {:.3}, x{:.3} ± {:.3}) from {} of {} pairs, \
         {:.0} % of the measured forces explained; written to {}",
        calibrated.name,
        calibrated.bending_stiffness_n_m2 * 1e3,
        c.nominal_n_m2 * 1e3,
        c.scale,
        c.scale_sd,
        c.pairs,
        rows.len(),
        c.explained * 100.0,
        args.out.display()
    );
    Ok(())
}
