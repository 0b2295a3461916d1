//! `hnet trace`: a trained model over every frame pair of a biplane DICOM cine, written as a
//! force trace CSV ([`hnet_dicom::trace_csv`], the page's format too). Each frame's estimate
//! follows the page's verdict ([`ForceCombination::estimate`]): combined with the blind physics
//! estimate from the network's own masks where the rod could be fitted (the C-arms from the
//! headers, a catalogue catheter, the fixture's nominal base fitted), else the force head alone;
//! each with its 90 % interval when the weights carry their calibration
//! ([`hnet_twin::model_facts`], `hnet eval --record`), each view read for its mask as that
//! calibration was measured. The trace holds no header value besides
//! the frame times, so no patient identifier.

use std::path::PathBuf;

use anyhow::{Context, bail};
use hnet_dicom::{Plane, TracePoint, trace_csv};
use hnet_twin::dataset::LoadedPair;
use hnet_twin::model_facts::recorded_name;
use hnet_twin::reconstruction::catalogue::{BENCH_CATHETER, CatalogueCatheter};
use hnet_twin::reconstruction::centreline::{CentrelineSettings, Mask, catheter_seen};
use hnet_twin::reconstruction::physics_force::{
    EstimateKind, ForceCombination, PhysicsSetup, TipForceEstimate, physics_estimate,
};
use hnet_twin::simulator::carm::Biplane;
use hnet_twin::simulator::scene::SceneSampling;
use hnet_units::TipForce;
use hnet_units::mask::MaskAveraging;

use crate::backend::BackendChoice;
use crate::cine::{grey_pair, open_cine};
use crate::data::StereoItem;
use crate::network::{load_weights, parse_mask_averaging, predict, read_views_as_recorded};
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
    /// The catheter the blind physics estimate assumes: a catalogue name or a catheter file
    /// (`hnet calibrate`'s output).
    #[arg(long, default_value = BENCH_CATHETER)]
    catheter: String,
    /// How each view is read for its mask (`single` or `mirrored`, as `hnet eval`). By default
    /// as the weights' calibration was measured, so that its intervals hold; another setting
    /// is allowed and said.
    #[arg(long, value_parser = parse_mask_averaging)]
    mask_averaging: Option<MaskAveraging>,
}

pub fn run(args: &TraceArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let mut model = load_weights(&args.weights, None, &device)?;
    let facts = read_views_as_recorded(&mut model, args.mask_averaging, &args.weights)?;
    let combination = facts.combination().copied();
    let catheter = CatalogueCatheter::find(&args.catheter)?;
    let cine = open_cine(&args.dicom_a, &args.dicom_b)?;
    let size = model.image_size;
    // The blind physics estimate needs the C-arms' geometry from the headers and a
    // calibrated combination; without either, the force head alone.
    let geometry_notes = cine.notes();
    let missing_geometry = cine
        .planes
        .iter()
        .any(|series| !series.geometry.missing.is_empty());
    let carm = |plane| cine.series(plane).geometry.carm.with_image_size(size);
    let views = Biplane {
        a: carm(Plane::A),
        b: carm(Plane::B),
    };
    // Where the headers' C-arm angles are not the ones the force head was trained at, its
    // force alone is no estimate ([`ForceCombination::estimate_at`]).
    let head_departures = facts
        .force_domain
        .as_ref()
        .map(|domain| domain.view_departures(&views))
        .unwrap_or_default();
    let setup = (!missing_geometry && combination.is_some()).then(|| {
        // The base where the weights' force learned it (the dataset's fixture), as `hnet eval`
        // calibrated the combination with; the twin's bench for weights that do not say.
        let scenes = facts
            .force_domain
            .as_ref()
            .map_or_else(SceneSampling::bench, |d| d.scenes.clone());
        PhysicsSetup::blind(
            [views.a.camera_matrix(), views.b.camera_matrix()],
            &catheter,
            &scenes.nominal_base(),
        )
    });
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
                let loaded = LoadedPair::of_images(images, size);
                StereoItem::new(loaded, TipForce::ZERO, false, (pair.frame + 1).to_string())
            })
            .collect();
        let mut outputs = Vec::with_capacity(chunk.len());
        predict(
            &model,
            &items,
            args.batch_size,
            &device,
            |_, masks, force| outputs.push((masks, force)),
        )?;
        use rayon::prelude::*;
        let estimates: Vec<anyhow::Result<Result<TipForceEstimate, String>>> = outputs
            .into_par_iter()
            .map(|(masks, force)| {
                let Some(head_n) = force else {
                    bail!(
                        "weights file '{}' holds a `{}` network, which estimates no force",
                        args.weights.display(),
                        model.spec.name()
                    );
                };
                Ok(frame_estimate(
                    head_n,
                    masks.as_ref(),
                    size,
                    combination.as_ref(),
                    setup.as_ref(),
                    &head_departures,
                ))
            })
            .collect();
        for (pair, estimate) in chunk.iter().zip(estimates) {
            trace.push(TracePoint {
                frame: pair.frame,
                time_s: pair.time_s,
                estimate: estimate?,
            });
        }
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
    let weights_name = recorded_name(&args.weights);
    hnet_twin::dataset::files::write_atomically(
        &args.out,
        trace_csv(&trace, &weights_name).as_bytes(),
    )
    .with_context(|| format!("cannot write {}", args.out.display()))?;
    let count = |kind| {
        trace
            .iter()
            .filter(|p| p.estimate.as_ref().is_ok_and(|e| e.kind == kind))
            .count()
    };
    let (combined, head) = (count(EstimateKind::Combined), count(EstimateKind::Head));
    let without = trace.len() - combined - head;
    eprintln!(
        "force trace of {} frame pairs written to {}: {combined} combined, {head} from the force \
         head alone, {without} without a force (a view shows no catheter, or the force head alone \
         at C-arm angles it was not trained at){}",
        pairs.len(),
        args.out.display(),
        match (&combination, missing_geometry) {
            (None, _) => format!(
                "; no intervals and no combined estimate: '{}' carries no calibration (record \
                 one with `hnet eval --record`)",
                args.weights.display()
            ),
            (Some(_), true) => format!("; no combined estimate: {}", geometry_notes.join("; ")),
            (Some(_), false) => String::new(),
        }
    );
    Ok(())
}

/// One frame's estimate from the network's force `head_n` (N) and masks (catheter probabilities
/// at `size`): none where a view shows no catheter; combined where the rod could be fitted to
/// the masks with `setup` and the weights carry a `combination`; else the head alone, but not at
/// C-arm angles it was not trained at (`head_departures`, [`ForceCombination::estimate_at`]).
fn frame_estimate(
    head_n: TipForce,
    masks: Option<&[Vec<f32>; 2]>,
    size: hnet_units::ImageSize,
    combination: Option<&ForceCombination>,
    setup: Option<&PhysicsSetup>,
    head_departures: &[String],
) -> Result<TipForceEstimate, String> {
    let masks = masks.map(|[a, b]| [a, b].map(|m| Mask::soft(size.width, size.height, m)));
    if let Some(masks) = &masks {
        let settings = CentrelineSettings::default();
        for (mask, view) in masks.iter().zip(["A", "B"]) {
            catheter_seen(mask, view, &settings).map_err(|why| hnet_units::with_causes(&why))?;
        }
    }
    let Some(combination) = combination else {
        return Ok(TipForceEstimate::uncalibrated(head_n));
    };
    let physics = masks
        .zip(setup)
        .and_then(|(masks, setup)| physics_estimate(masks, setup).ok())
        .map(|estimate| {
            let fit = estimate.fit;
            (fit.force_n, fit.force_sd_n)
        });
    combination.estimate_at(head_n, physics, head_departures)
}
