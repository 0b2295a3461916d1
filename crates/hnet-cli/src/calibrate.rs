//! `hnet calibrate`: a catheter's bending stiffness from a few pairs labelled with a measured tip
//! force (a bench with a force sensor, as the paper had), for the blind force estimate.
//!
//! Each pair's catheter is read blind from its label masks ([`PhysicsSetup::blind`]: the
//! catalogue catheter, the base fitted from its nominal pose, the C-arms from the pair's recorded
//! geometry), and one stiffness scale is fitted to the measured forces
//! ([`hnet_twin::catalogue::calibrate_stiffness`]; why one scale is all images leave open is in
//! that module). The result is a catheter file that `hnet eval --catheter` reads.

use std::path::PathBuf;

use anyhow::Context;
use hnet_twin::catalogue::{BENCH_CATHETER, CatalogueCatheter, calibrate_stiffness};
use hnet_twin::centreline::Mask;
use hnet_twin::dataset::Dataset;
use hnet_twin::files::write_atomically;
use hnet_twin::physics_force::{PhysicsSetup, physics_estimate};
use hnet_twin::simulate::{blind_cameras, nominal_base, read_pair_carms};
use rayon::prelude::*;

use crate::evaluation::parse_split;
use hnet_twin::dataset::Split;

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
}

/// A pair's measured force and its blind estimate, N.
type ForcePair = ([f64; 3], [f64; 3]);

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let catheter = CatalogueCatheter::find(&args.catheter)?;
    let dataset = Dataset::open(&args.data)?;
    let rows: Vec<_> = dataset
        .rows
        .iter()
        .filter(|row| args.split.is_none_or(|split| row.split == split))
        .take(args.pairs.unwrap_or(usize::MAX))
        .collect();
    anyhow::ensure!(
        !rows.is_empty(),
        "{}: no pairs to calibrate on",
        args.data.display()
    );
    let base = nominal_base(&dataset);
    let size = dataset.header.image_size;
    // Per pair: (measured force, blind estimate) in newtons, or why it gave none.
    let read: Vec<Result<ForcePair, String>> = rows
        .par_iter()
        .map(|row| {
            let carms = read_pair_carms(&dataset, &row.id).map_err(|e| e.to_string())?;
            let pair = dataset.load_pair(row, None).map_err(|e| e.to_string())?;
            let setup = PhysicsSetup::blind(blind_cameras(&carms, size), &catheter, &base);
            let masks =
                [&pair.mask_a, &pair.mask_b].map(|m| Mask::soft(size.width, size.height, m));
            let estimate =
                physics_estimate(masks, &setup).map_err(|e| format!("pair {}: {e}", row.id))?;
            Ok((row.force_n, estimate.fit.force_n.0))
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
