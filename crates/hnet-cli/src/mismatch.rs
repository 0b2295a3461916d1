//! `hnet study mismatch`: the blind force estimate on test data its model does not share.
//!
//! Each set of the suite changes one thing the estimators assume, within a range a real bench
//! or catheter lab would show, simulates it (seeded; resumed if the folder holds part of it) and
//! evaluates a model on it blind ([`crate::evaluation::evaluate`]: the catalogue's bench
//! catheter, the base fitted from the fixture's nominal pose, the combination calibrated on the
//! set's own val split). One table: per set, the force head, the physics estimate from the
//! network's masks and the combined estimate per axis, the share of pairs with an estimate, and
//! how often the combined 90 % interval covers the true force.
//!
//! The suite covers the catheter off its catalogue values, the base anywhere within the page's
//! ranges, C-arm header errors (angles, distances, the two planes' isocentres apart), motion
//! between the two planes' exposures, imaging (low-dose noise, blur, scatter and veiling glare,
//! the display's grey curve), real radiograph backgrounds, and a rod the fit does not model: a
//! rigid tip electrode, a base held in a sheath, the force applied on the tip's surface with
//! friction; and a catheter foreshortened towards one source.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::tensor::Device;
use hnet_model::metrics::ForceMetrics;
use hnet_twin::dataset::Split;
use hnet_twin::reconstruction::MaskOrigin;
use hnet_twin::reconstruction::catalogue::{BENCH_CATHETER, CatalogueCatheter};
use hnet_twin::simulator::carm::HeaderError;
use hnet_twin::simulator::render::XRayDetector;
use hnet_twin::simulator::scene::{BaseLean, Modality, SceneSampling, Sheath};
use serde::Serialize;

use crate::backend::BackendChoice;
use crate::evaluation::{EvalOptions, Evaluation, evaluate};
use crate::network::{load_weights, parse_mask_averaging, read_views_as_recorded};
use crate::simulate::{Scenes, SimulateArgs};
use hnet_model::mask_averaging::MaskAveraging;

/// `hnet study mismatch`.
#[derive(clap::Args, Debug)]
pub struct MismatchArgs {
    /// Weights to evaluate (`model.bpk`, or the page's bundled weights).
    #[arg(long)]
    weights: PathBuf,
    /// Folder for the suite's datasets and its table (`mismatch.md`, `mismatch.json`).
    #[arg(long)]
    out: PathBuf,
    /// Pairs simulated per set (80 % evaluated, 10 % calibrate the combination).
    #[arg(long, default_value_t = 300)]
    samples: usize,
    /// Seed of the first set (each set adds its index).
    #[arg(long, default_value_t = 60)]
    seed: u64,
    /// Chest radiographs for the `chest` set (files or folders); the set is left out without.
    #[arg(long = "background")]
    backgrounds: Vec<PathBuf>,
    /// Only these sets (comma-separated names); all by default.
    #[arg(long, value_delimiter = ',')]
    sets: Vec<String>,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// How many ways each view is read for its mask (`hnet eval --mask-averaging`); by default
    /// as the weights' recorded calibration was measured.
    #[arg(long, value_parser = parse_mask_averaging)]
    mask_averaging: Option<MaskAveraging>,
}

/// One set of the suite.
struct MismatchSet {
    name: &'static str,
    /// What differs from the estimators' model, and why that range is realistic.
    why: &'static str,
    scenes: SceneSampling,
    header_error: HeaderError,
    chest: bool,
    /// The X-ray detector the set is imaged with (the twin's default otherwise).
    detector: Option<XRayDetector>,
    /// Whether the backgrounds' patch grid starts at a random place (`hnet simulate
    /// --random-patch-grid`).
    random_patch_grid: bool,
}

/// The suite: each set departs from the bench in one way.
fn suite() -> Vec<MismatchSet> {
    let bench = SceneSampling::bench;
    let stiffness = |factor: f64| SceneSampling {
        bending_stiffness_n_m2: [0.6e-3 * factor; 2],
        ..bench()
    };
    let set = |name, why, scenes| MismatchSet {
        name,
        why,
        scenes,
        header_error: HeaderError::default(),
        chest: false,
        detector: None,
        random_patch_grid: false,
    };
    let imaged = |name, why, detector: XRayDetector| MismatchSet {
        detector: Some(detector),
        ..set(name, why, bench())
    };
    let detector = XRayDetector::default;
    vec![
        set("nominal", "the bench as the estimators assume it", bench()),
        set(
            "stiffness+30",
            "EI 30 % above the catalogue's: makers quote stiffness within tens of percent, and \
             it drifts with temperature and use",
            stiffness(1.3),
        ),
        set(
            "stiffness-30",
            "EI 30 % below the catalogue's",
            stiffness(0.7),
        ),
        set(
            "length+5mm",
            "the flexible section 5 mm longer: where the deflectable part ends is not sharp",
            SceneSampling {
                length_mm: [55.0; 2],
                ..bench()
            },
        ),
        set(
            "precurve",
            "pre-curved to a 45 mm radius instead of 60 mm: a shaped tip relaxes and is reshaped",
            SceneSampling {
                precurvature_per_mm: [1.0 / 45.0; 2],
                ..bench()
            },
        ),
        set(
            "base-anywhere",
            "the base within the page's ranges (6 mm, 25° of tilt) instead of the fixture's 1 mm \
             and 2°: a catheter through a sheath in a patient",
            SceneSampling {
                base_jitter_mm: 6.0,
                base_tilt_deg: 25.0,
                ..bench()
            },
        ),
        MismatchSet {
            header_error: HeaderError {
                angle_deg: 2.0,
                ..HeaderError::default()
            },
            ..set(
                "carm-angles-2deg",
                "each C-arm angle read 2° off at most: a header's stated angle against the \
                 gantry's true one",
                bench(),
            )
        },
        MismatchSet {
            header_error: HeaderError {
                distance_mm: 20.0,
                ..HeaderError::default()
            },
            ..set(
                "carm-distances-20mm",
                "source distances read 20 mm off at most: the isocentre's depth in the patient is \
                 not where the header puts it",
                bench(),
            )
        },
        MismatchSet {
            chest: true,
            ..set(
                "chest",
                "real chest radiographs behind the catheter instead of the phantom",
                bench(),
            )
        },
        MismatchSet {
            header_error: HeaderError {
                isocentre_mm: 2.0,
                ..HeaderError::default()
            },
            ..set(
                "isocentres-2mm",
                "plane B's isocentre up to 2 mm from plane A's along each axis, where the headers \
                 put both at one point: biplane isocentres are calibrated to meet within 1-2 mm \
                 and drift with wear",
                bench(),
            )
        },
        set(
            "exposure-motion",
            "the catheter moved by up to 1 mm along each axis between the two planes' \
             exposures: biplane planes expose in turn, about 30 ms apart at 15 frames per second, \
             while the heart carries the catheter at tens of mm/s",
            SceneSampling {
                exposure_motion_mm: 1.0,
                ..bench()
            },
        ),
        imaged(
            "low-dose",
            "a fifth of the twin's dose (500 photons per pixel for 2,500): quantum noise 2.2 \
             times stronger, as in low-dose pulsed fluoroscopy",
            XRayDetector {
                photons_per_pixel: 500.0,
                ..detector()
            },
        ),
        imaged(
            "blur",
            "detector and focal-spot blur of 1.5 px (σ) for 0.6: a larger focal spot at higher \
             magnification, or an older image intensifier",
            XRayDetector {
                blur_px: 1.5,
                ..detector()
            },
        ),
        imaged(
            "scatter-glare",
            "30 % of the signal scatter and veiling glare, spread over the frame: scatter-to-\
             primary ratios behind an anti-scatter grid are 0.2-0.5 in cardiac imaging",
            XRayDetector {
                scatter_fraction: 0.3,
                ..detector()
            },
        ),
        imaged(
            "contrast",
            "the display's grey curve lifted (γ 0.6): another system's look-up table or a \
             window set brighter",
            XRayDetector {
                display_gamma: 0.6,
                ..detector()
            },
        ),
        // Added after the sets above, so that theirs keep their seeds.
        set(
            "tip-electrode",
            "the 3.5 mm platinum-iridium tip electrode rigid (50 times the shaft's EI) where the \
             fit bends the shaft to its end: every ablation catheter has one, 3.5-8 mm long",
            SceneSampling {
                tip_electrode_stiffness: 50.0,
                ..bench()
            },
        ),
        set(
            "sheath",
            "the catheter leaves a sheath whose last 20 mm stand free (sheath and catheter \
             together 4 times the catheter's EI) where the fit clamps it at the sheath's end: \
             a catheter through a steerable sheath, the sheath's end turning under the load",
            SceneSampling {
                sheath: Some(Sheath {
                    free_length_mm: 20.0,
                    stiffness_factor: 4.0,
                }),
                ..bench()
            },
        ),
        set(
            "tip-contact",
            "the force applied where the tip's rounded end touches a wall (up to 1.7 mm off the \
             centreline's end, a tip moment the fit does not model), the wall's normal anywhere \
             within the friction cone of the force (μ 0.3: a wet polymer or metal tip on \
             endocardium, 0.1-0.5)",
            SceneSampling {
                contact_friction: Some(0.3),
                ..bench()
            },
        ),
        set(
            "foreshortened",
            "the fixture leant 45° towards plane A's source, so that plane A sees the flexible \
             section at 71 % of its length and its bend partly in depth: a catheter pointing at \
             one of the tubes, as in a view chosen for another structure",
            SceneSampling {
                base_lean: Some(BaseLean {
                    tilt_deg: 45.0,
                    azimuth_deg: 0.0,
                }),
                ..bench()
            },
        ),
        MismatchSet {
            random_patch_grid: true,
            ..set(
                "background-edges",
                "the background's straight edges (the shuffled patches') anywhere in the view, \
                 where the bench's fall every quarter of it: a collimator blade, a wedge filter \
                 or another device's edge can cross a view at any place",
                bench(),
            )
        },
    ]
}

/// One row of the table.
#[derive(Debug, Clone, Serialize)]
pub struct MismatchRow {
    /// The set's name.
    pub set: String,
    /// What differs.
    pub why: String,
    /// Pairs evaluated.
    pub pairs: usize,
    /// The force head's Table I.
    pub head: Option<ForceMetrics>,
    /// The physics estimate from the network's masks, on the pairs it fitted.
    pub physics: Option<ForceMetrics>,
    /// The combined estimate, same pairs.
    pub combined: Option<ForceMetrics>,
    /// Share of pairs with a physics (hence combined) estimate, 0-1.
    pub estimated: f64,
    /// Share of pairs whose true force lies in the combined 90 % interval, per axis.
    pub coverage_90: Option<[f64; 3]>,
    /// Catheter IoU of the network's masks, views A and B.
    pub catheter_iou: Option<[f64; 2]>,
}

fn row(set: &MismatchSet, e: &Evaluation) -> MismatchRow {
    let network = e
        .physics
        .iter()
        .find(|check| check.masks == MaskOrigin::Predicted);
    MismatchRow {
        set: set.name.into(),
        why: set.why.into(),
        pairs: network.map_or(0, |c| c.pairs),
        head: e.force,
        physics: network.and_then(|c| c.force),
        combined: network.and_then(|c| c.combined_force),
        estimated: network.map_or(0.0, |c| c.fitted as f64 / c.pairs.max(1) as f64),
        coverage_90: network.and_then(|c| c.combined_coverage_90),
        catheter_iou: e
            .segmentation
            .as_ref()
            .map(|[a, b]| [a.catheter.iou, b.catheter.iou]),
    }
}

/// R² per axis and their mean, `x / y / z (mean)`.
fn r2_text(m: &Option<ForceMetrics>) -> String {
    match m {
        Some(m) => {
            let axis = |i: usize| m.axes[i].r2.map_or("n/a".into(), |v| format!("{v:.2}"));
            let mean = m.overall.r2.map_or("n/a".into(), |v| format!("{v:.2}"));
            format!("{} / {} / {} ({mean})", axis(0), axis(1), axis(2))
        }
        None => "n/a".into(),
    }
}

/// The table as markdown.
pub fn markdown(weights: &Path, rows: &[MismatchRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Blind force estimate of `{}` on the mismatch suite (R² x / y / z (mean); the physics \
         and combined estimates on the pairs that got one)\n",
        weights.display()
    );
    let _ = writeln!(
        s,
        "| set | pairs | force head | physics from H-Net's masks | combined | with an estimate | \
         90 % interval covers | catheter IoU A / B |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | --- | --- | --- | --- |");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.1} % | {} | {} |",
            r.set,
            r.pairs,
            r2_text(&r.head),
            r2_text(&r.physics),
            r2_text(&r.combined),
            r.estimated * 100.0,
            r.coverage_90.map_or("n/a".into(), |c| c
                .map(|v| format!("{:.0} %", v * 100.0))
                .join(" / ")),
            r.catheter_iou
                .map_or("n/a".into(), |[a, b]| format!("{a:.3} / {b:.3}")),
        );
    }
    let _ = writeln!(s);
    for r in rows {
        let _ = writeln!(s, "- `{}`: {}.", r.set, r.why);
    }
    s
}

pub fn run(args: &MismatchArgs) -> anyhow::Result<()> {
    let device: Device = args.backend.device()?;
    let mut model = load_weights(&args.weights, None, &device)?;
    read_views_as_recorded(&mut model, args.mask_averaging, &args.weights)?;
    let catheter = CatalogueCatheter::find(BENCH_CATHETER)?;
    // Each set's seed is the first plus its place in the whole suite, so that a set gives the
    // same pairs whether it runs alone or with the others.
    let suite: Vec<(usize, MismatchSet)> = suite()
        .into_iter()
        .enumerate()
        .filter(|(_, set)| args.sets.is_empty() || args.sets.iter().any(|name| name == set.name))
        .filter(|(_, set)| !set.chest || !args.backgrounds.is_empty())
        .collect();
    anyhow::ensure!(
        !suite.is_empty(),
        "no set of the suite is named {:?}",
        args.sets
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create '{}'", args.out.display()))?;
    let mut rows = Vec::new();
    for (index, set) in &suite {
        let data = args.out.join(set.name);
        crate::simulate::run(&SimulateArgs {
            modality: Modality::Xray2,
            samples: args.samples,
            size: model.image_size.width,
            seed: args.seed + *index as u64,
            out: data.clone(),
            backgrounds: if set.chest {
                args.backgrounds.clone()
            } else {
                Vec::new()
            },
            mask: None,
            scenes: Scenes::Preset(Box::new(set.scenes.clone())),
            scene_sampling: None,
            detector: set.detector,
            random_patch_grid: set.random_patch_grid,
            shard: None,
        })
        .with_context(|| format!("simulating the `{}` set", set.name))?;
        let (evaluation, _) = evaluate(
            &model,
            &data,
            Split::Train,
            &device,
            16,
            &EvalOptions {
                physics_check: true,
                catheter: Some(catheter.clone()),
                header_error: set.header_error,
                ..EvalOptions::default()
            },
        )
        .with_context(|| format!("evaluating the `{}` set", set.name))?;
        let r = row(set, &evaluation);
        eprintln!("{}", markdown(&args.weights, std::slice::from_ref(&r)));
        rows.push(r);
    }
    let md = markdown(&args.weights, &rows);
    std::fs::write(args.out.join("mismatch.md"), &md)
        .with_context(|| format!("cannot write '{}'", args.out.join("mismatch.md").display()))?;
    std::fs::write(
        args.out.join("mismatch.json"),
        serde_json::to_vec_pretty(&rows)?,
    )
    .with_context(|| format!("cannot write into '{}'", args.out.display()))?;
    print!("{md}");
    Ok(())
}
