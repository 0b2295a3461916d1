//! `hnet eval`: the paper's Table I (force) and Table II (segmentation) for a trained run on a
//! dataset split, as JSON and markdown, with the per-pair predictions kept for `hnet report`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::module::Module;
use burn::tensor::Device;
use hnet_model::catheter_entry::EntrySetting;
use hnet_model::mask_averaging::MaskAveraging;
use hnet_model::metrics::{
    ForceAccumulator, ForceMetrics, SegmentationAccumulator, SegmentationMetrics,
};
use hnet_model::predictor::{PairOutput, Predictor};
use hnet_twin::dataset::{Dataset, Split, SquareSymmetry};
use hnet_units::ImageSize;
use serde::{Deserialize, Serialize};

mod files;
mod physics;
mod record;
pub use files::{PairPrediction, markdown, predictions_csv, write_predicted_masks};
use physics::{calibrate_combination, physics_checks};
use record::record_facts;

use crate::backend::BackendChoice;
use crate::data::StereoSplit;
use crate::network::{
    load_run, load_weights, parse_mask_averaging, predict_entry, read_views_as_recorded,
};
use crate::physics_check::{self, BlindEstimator, Estimator, PhysicsEvaluation};
use crate::run_dir::RunDir;
use hnet_twin::dataset::simulate::nominal_base;
use hnet_twin::model_facts::ModelFacts;
use hnet_twin::reconstruction::MaskOrigin;
use hnet_twin::reconstruction::catalogue::{BENCH_CATHETER, CatalogueCatheter};
use hnet_twin::simulator::carm::{Biplane, HeaderError};

#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("model").required(true).args(["run", "weights"])))]
pub struct EvalArgs {
    /// Run folder of `hnet train` (its `model.bpk` is evaluated, and the tables and predictions
    /// are saved there).
    #[arg(long)]
    run: Option<PathBuf>,
    /// A weights file (`model.bpk`, or the page's bundled weights) to evaluate instead of a run;
    /// needs `--data`. H-Net's weights know their input size; a baseline's need `--size`.
    #[arg(long, requires = "data")]
    weights: Option<PathBuf>,
    /// Input size (pixels, square) of a baseline's weights given with `--weights`.
    #[arg(long, requires = "weights")]
    size: Option<usize>,
    /// Dataset folder (the one the run was trained on by default).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Which split.
    #[arg(long, default_value = "test", value_parser = parse_split)]
    split: Split,
    /// Print JSON instead of markdown.
    #[arg(long)]
    json: bool,
    /// Skip the physics check (3D reconstruction and rod fit of every simulated pair, from the
    /// true and the predicted masks).
    #[arg(long)]
    no_physics: bool,
    /// Also write each pair's true force, the network's and the physics estimate from its masks,
    /// and its masks' catheter IoU per view, to this CSV file, one row per pair (empty columns
    /// for a head the network lacks; a run folder keeps it as `predictions-<split>.csv` anyway).
    #[arg(long)]
    predictions: Option<PathBuf>,
    /// Also write each pair's predicted masks into this folder (`<id>_predicted_mask_a.png`, at
    /// the network's input size), with error maps against the label masks (`<id>_errors_a.png`:
    /// white the catheter found, blue missed, red spurious).
    #[arg(long)]
    masks: Option<PathBuf>,
    /// Dataset whose pairs calibrate the combined force (the network's error and the physics
    /// estimate's, each axis weighted by the inverse of its error variance): its val split (its
    /// test split when that is the split evaluated here). By default the evaluated dataset.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// Pairs per batch.
    #[arg(long, default_value_t = 16)]
    batch_size: usize,
    /// Turn both views, each with its label mask, this many quarter turns clockwise before the
    /// network sees them (0 leaves them as they are): how much the masks depend on the
    /// catheter's direction in the view. Square networks that segment; the force is not
    /// evaluated (turned views no longer come from their C-arms) and nothing is saved into a
    /// run folder.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=3))]
    turn_views: u8,
    /// The edge through which the catheter enters the views (`bottom`, `left`, `top`, `right`;
    /// two, comma-separated, for views A and B), or `auto` to find it per view: read as it
    /// is, and at the other three quarter turns when its mask does not reach the bottom edge,
    /// keeping the turn with the most catheter pixels (`every-turn`: all four turns of every
    /// view, four times the work). Each view is turned so that its catheter comes up from the bottom, as in training,
    /// and its masks turned back; the force head's estimate is kept only for pairs read as they
    /// are. Square networks that segment; nothing is saved into a run folder unless `bottom`.
    #[arg(long, default_value = "bottom", value_parser = parse_entry)]
    catheter_entry: EntrySetting,
    /// How many ways each view is read for its mask, the readings' catheter probabilities
    /// averaged: `single`, or `mirrored` (the view and its left-right mirror image, twice the
    /// network's work). The force head reads the views as given. Mirrored only for networks
    /// whose training views were left-right symmetric (the C-arm bench's; not the paper
    /// bench's). By default as the weights' recorded calibration was measured (one reading for
    /// weights that record none); `--record` records the setting used.
    #[arg(long, value_parser = parse_mask_averaging)]
    mask_averaging: Option<MaskAveraging>,
    /// The catheter the blind physics estimate assumes: a catalogue name or a catheter file
    /// (`hnet calibrate`'s output).
    #[arg(long, default_value = BENCH_CATHETER, conflicts_with = "oracle")]
    catheter: String,
    /// Hand the physics estimate each pair's recorded catheter and exact base pose (the twin's
    /// answers, which no user has) instead of reading it blind. Every table and JSON field then
    /// says `oracle`.
    #[arg(long)]
    oracle: bool,
    /// Read each pair's C-arm angles off by up to this many degrees (uniform, per view and
    /// pair): a header's error, for the mismatch suite. Blind only.
    #[arg(long, default_value_t = 0.0, conflicts_with = "oracle")]
    carm_angle_error: f64,
    /// Read each pair's C-arm distances (source to isocentre, source to detector) off by up to
    /// this many millimetres. Blind only.
    #[arg(long, default_value_t = 0.0, conflicts_with = "oracle")]
    carm_distance_error: f64,
    /// Read plane B's isocentre as plane A's while it is off by up to this many millimetres
    /// along each axis (the two planes' isocentres apart). Blind only.
    #[arg(long, default_value_t = 0.0, conflicts_with = "oracle")]
    carm_isocentre_error: f64,
    /// Record the measured force error, and the combination's calibration with its 90 %
    /// intervals, in the weights file evaluated (the run's `model.bpk`, or `--weights`): the
    /// facts the page and `hnet trace` read (`hnet_twin::model_facts`). The file is rewritten
    /// atomically with the same parameters.
    /// Measured blind, as the page and `hnet trace` read pairs: not with `--oracle`.
    #[arg(long, conflicts_with_all = ["oracle", "turn_views", "carm_angle_error", "carm_distance_error", "carm_isocentre_error"])]
    record: bool,
    /// With `--record`: also record this twin dataset's ranges as the data the weights' force
    /// was trained on (for weights written before `hnet train` recorded it).
    #[arg(long, requires = "record")]
    trained_on: Option<PathBuf>,
}

fn parse_entry(text: &str) -> Result<EntrySetting, String> {
    EntrySetting::from_text(text).ok_or_else(|| {
        format!("`{text}` is not auto, an edge (bottom, left, top, right) or two edges `A,B`")
    })
}

pub fn parse_split(text: &str) -> Result<Split, String> {
    Split::parse(text).ok_or_else(|| format!("`{text}` is not train, val or test"))
}

/// The paper's two tables for one model on one split.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Evaluation {
    /// Architecture name.
    pub architecture: String,
    /// Parameter count.
    pub params: usize,
    /// Dataset folder.
    pub data: PathBuf,
    /// Split evaluated.
    pub split: String,
    /// Input size, pixels.
    pub image_size: ImageSize,
    /// Table I, for networks with a force head.
    pub force: Option<ForceMetrics>,
    /// Table II per head (view A, view B), for networks that segment.
    pub segmentation: Option<[SegmentationMetrics; 2]>,
    /// Table II over both heads together.
    pub segmentation_mean: Option<SegmentationMetrics>,
    /// The physics check of simulated pairs: from the true masks, and from the predicted ones
    /// for networks that segment (empty when skipped or when the data was not simulated).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub physics: Vec<PhysicsEvaluation>,
    /// The split the combined force was calibrated on, when there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_split: Option<String>,
    /// The dataset it was calibrated on, when not the evaluated one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_data: Option<PathBuf>,
    /// Quarter turns clockwise given to both views and their label masks before the network
    /// saw them (`hnet eval --turn-views`); 0 for the views as they are.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub view_turns: u8,
    /// How each view's catheter entry edge was found (`hnet eval --catheter-entry`), when not
    /// as trained (from the bottom).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub catheter_entry: Option<EntryUse>,
    /// How many ways each view was read for its mask (`hnet eval --mask-averaging`); files
    /// written before it existed read as `single`, which is what they were.
    #[serde(default, skip_serializing_if = "MaskAveraging::is_single")]
    pub mask_averaging: MaskAveraging,
    /// What the physics estimate was told: `blind` (a catalogue catheter, the base fitted) or
    /// `oracle` (each pair's recorded catheter and base). Files written before the blind
    /// estimate existed read as `oracle`, which is what they were.
    #[serde(default = "oracle_name")]
    pub estimator: String,
    /// The catheter a blind estimate assumed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub catheter: Option<CatalogueCatheter>,
    /// The error the C-arm settings were read with (a blind estimate in the mismatch suite).
    #[serde(default, skip_serializing_if = "HeaderError::is_none")]
    pub header_error: HeaderError,
    /// Evaluated pairs whose C-arm angles are not the ones the weights' force head was trained
    /// at (their file's facts): there the product shows its force only combined with the
    /// physics estimate, never alone (`ForceCombination::estimate_at`), so Table I measures
    /// the head on them without being what a user is shown. `None` where the weights record no
    /// training domain or the pairs no twin records.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pairs_at_other_angles: Option<usize>,
}

fn oracle_name() -> String {
    "oracle".into()
}

/// How [`Evaluation`]'s pairs were read for their catheters' entry edges.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EntryUse {
    /// The setting (`auto`, or the edges of views A and B).
    pub setting: String,
    /// Views A and B read turned (entering through another edge than the bottom).
    pub views_read_turned: [usize; 2],
    /// Views A and B read at the edge their catheter enters through, when the views were
    /// turned by a known amount (`--turn-views`, or none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub views_placed_right: Option<[usize; 2]>,
    /// Readings of views A and B the search took: the pairs' count when each view was read
    /// once, four times it when read at every turn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_readings: Option<[usize; 2]>,
    /// Pairs evaluated.
    pub pairs: usize,
}

fn is_zero(turns: &u8) -> bool {
    *turns == 0
}

/// What [`evaluate`] checks and writes besides the network's own tables.
#[derive(Debug, Clone, Default)]
pub struct EvalOptions {
    /// Run the physics check on simulated pairs.
    pub physics_check: bool,
    /// The dataset that calibrates the combined force (default: the evaluated one).
    pub calibration: Option<PathBuf>,
    /// A folder to write each pair's predicted masks into, with their error maps
    /// ([`write_predicted_masks`]).
    pub masks: Option<PathBuf>,
    /// Quarter turns clockwise of both views and their label masks before the network sees
    /// them (0-3): masks only, no force or physics check.
    pub view_turns: u8,
    /// How each view's catheter entry edge is found ([`predict_entry`]).
    pub entry: EntrySetting,
    /// The catheter a blind physics estimate assumes; `None` hands it each pair's record
    /// instead (the oracle).
    pub catheter: Option<CatalogueCatheter>,
    /// How wrong a blind estimate reads each pair's C-arm settings (none by default).
    pub header_error: HeaderError,
}

/// Evaluates a trained model on a split; returns the tables and the per-pair forces. With
/// `options.physics_check`, simulated pairs also get the physics check, and a network that
/// segments and estimates a force the combined estimate, calibrated on other pairs
/// ([`calibration_split`]). With `options.masks`, each pair's predicted masks and error maps
/// are written there ([`write_predicted_masks`]); after an error the folder keeps what was
/// written before it.
pub fn evaluate(
    model: &Predictor,
    data: &Path,
    split: Split,
    device: &Device,
    batch_size: usize,
    options: &EvalOptions,
) -> anyhow::Result<(Evaluation, Vec<PairPrediction>)> {
    let dataset = Dataset::open(data)?;
    let estimator = match &options.catheter {
        Some(catheter) => Estimator::Blind(Box::new(BlindEstimator {
            catheter: catheter.clone(),
            nominal_base: nominal_base(&dataset),
            header_error: options.header_error,
            seed: 0x5EED,
        })),
        None => Estimator::Oracle,
    };
    let turn = SquareSymmetry {
        quarter_turns: options.view_turns % 4,
        mirrored: false,
    };
    let turned = turn != SquareSymmetry::IDENTITY;
    if turned {
        anyhow::ensure!(
            model.spec.heads().0,
            "--turn-views measures masks; a `{}` network gives none",
            model.spec.name()
        );
        anyhow::ensure!(
            model.image_size.width == model.image_size.height,
            "--turn-views needs a square network; this one takes {} images",
            model.image_size
        );
    }
    let pairs = StereoSplit::load_turned(&dataset, split, model.image_size, None, turn)?;
    anyhow::ensure!(
        !pairs.items.is_empty(),
        "{} has no pairs in its {} split",
        data.display(),
        split.name()
    );
    let mut heads = [
        SegmentationAccumulator::new(),
        SegmentationAccumulator::new(),
    ];
    let mut forces = ForceAccumulator::new();
    let mut predictions = Vec::new();
    let mut error = None;
    let records = if options.physics_check && turned {
        eprintln!("views turned: no physics check (they no longer come from their C-arms)");
        None
    } else if options.physics_check {
        let ids: Vec<&str> = pairs.items.iter().map(|item| &*item.id).collect();
        let records = physics_check::read_records(&dataset, &ids);
        if records.is_none() {
            eprintln!(
                "{} was not simulated (no twin records): no physics check",
                data.display()
            );
        }
        records
    } else {
        None
    };
    if let Some(folder) = &options.masks {
        anyhow::ensure!(
            model.spec.heads().0,
            "--masks: a `{}` network gives no masks",
            model.spec.name()
        );
        std::fs::create_dir_all(folder)
            .with_context(|| format!("cannot create the masks folder '{}'", folder.display()))?;
    }
    // Per pair, what the physics check reads: the predicted masks and force.
    let mut predicted: Vec<PairOutput> = Vec::new();
    let entry_counts = predict_entry(
        model,
        &pairs.items,
        batch_size,
        device,
        options.entry,
        |item, masks, force| {
            if records.is_some() {
                predicted.push(PairOutput {
                    masks: masks.clone(),
                    force,
                });
            }
            // After the first error nothing more is computed or written.
            if error.is_some() {
                return;
            }
            let mut catheter_iou = None;
            if let Some(masks) = masks {
                let targets = [&item.mask_a, &item.mask_b].map(|t| {
                    t.iter()
                        .map(|&v| f32::from(v) / 255.0)
                        .collect::<Vec<f32>>()
                });
                let mut iou = [1.0; 2];
                for (((head, predicted), target), iou) in
                    heads.iter_mut().zip(&masks).zip(&targets).zip(&mut iou)
                {
                    let mut this_pair = SegmentationAccumulator::new();
                    if let Err(e) = this_pair.push(predicted, target) {
                        error = Some(anyhow::Error::new(e).context(format!("pair {}", item.id)));
                        return;
                    }
                    head.merge(&this_pair);
                    if let Some(m) = this_pair.finish() {
                        *iou = m.catheter.iou;
                    }
                }
                catheter_iou = Some(iou);
                if let Some(folder) = &options.masks
                    && let Err(e) =
                        write_predicted_masks(folder, &item.id, model.image_size, &masks, &targets)
                {
                    error = Some(e);
                    return;
                }
            }
            // Turned views no longer show their C-arms' projections: no force is read there.
            let force = force.filter(|_| !turned);
            if let Some(force) = force {
                forces.push(force, item.force_n);
            }
            predictions.push(PairPrediction {
                id: item.id.to_string(),
                truth: item.force_n,
                predicted: force,
                physics: None,
                physics_sd: None,
                physics_correlation: None,
                combined: None,
                combined_sd: None,
                combined_90: None,
                catheter_iou,
            });
        },
    )?;
    if let Some(e) = error {
        return Err(e);
    }
    let (segments, force_head) = model.spec.heads();
    let segmentation = segments.then(|| heads.map(|h| h.finish().expect("pairs were seen")));
    let segmentation_mean = segments.then(|| {
        let mut both = heads[0];
        both.merge(&heads[1]);
        both.finish().expect("pairs were seen")
    });
    let calibration = match (&records, force_head_and_masks(model)) {
        (Some(_), true) => {
            // Another dataset calibrates on its val split; the evaluated one on the split next
            // to the one evaluated.
            let other = match &options.calibration {
                Some(path) => Some(Dataset::open(path)?).filter(|d| d.root != dataset.root),
                None => None,
            };
            let (calibration_data, calibration_split) = match other {
                Some(other) => (other, Split::Val),
                None => (dataset.clone(), calibration_split(split)),
            };
            calibrate_combination(
                model,
                &calibration_data,
                calibration_split,
                device,
                batch_size,
                &estimator,
            )?
        }
        _ => None,
    };
    // Pairs at C-arm angles the force head was not trained at.
    let pairs_at_other_angles = records.as_ref().and_then(|records| {
        let domain = ModelFacts::read(&model.header.provenance)
            .ok()?
            .force_domain?;
        Some(
            records
                .iter()
                .filter(|r| {
                    let views = Biplane {
                        a: r.views[0].carm,
                        b: r.views[1].carm,
                    };
                    !domain.view_departures(&views).is_empty()
                })
                .count(),
        )
    });
    let physics = match &records {
        Some(records) => physics_checks(
            &dataset,
            split,
            model,
            &pairs.items,
            &predicted,
            records,
            (&estimator, calibration.as_ref().map(|(_, c)| c)),
        )?,
        None => Vec::new(),
    };
    // The physics estimate from the network's masks, beside its force (both are per item).
    if let Some(from_network) = physics.iter().find(|c| c.masks == MaskOrigin::Predicted)
        && from_network.force_per_pair.len() == predictions.len()
    {
        for (prediction, physics) in predictions.iter_mut().zip(&from_network.force_per_pair) {
            prediction.physics = physics.map(|p| p.force_n);
            prediction.physics_sd = physics.and_then(|p| p.sd_n);
            prediction.physics_correlation = physics.and_then(|p| p.correlation);
            let combined = physics
                .zip(from_network.combination)
                .zip(prediction.predicted)
                .map(|((p, c), network)| {
                    let (force, sd) = c.combine_with_sd(network, p.force_n, p.sd_n);
                    (force, sd, c.interval_90_n(sd))
                });
            prediction.combined = combined.map(|(force, ..)| force);
            prediction.combined_sd = combined.map(|(_, sd, _)| sd);
            prediction.combined_90 = combined.map(|(.., half)| half);
        }
    }
    Ok((
        Evaluation {
            architecture: model.spec.name().to_string(),
            params: model.net.num_params(),
            data: data.to_path_buf(),
            split: split.name().to_string(),
            image_size: model.image_size,
            force: if force_head && !turned {
                forces.finish()
            } else {
                None
            },
            segmentation,
            segmentation_mean,
            physics,
            calibration_split: calibration.map(|(split, _)| split.name().to_string()),
            calibration_data: calibration
                .is_some()
                .then(|| options.calibration.clone())
                .flatten(),
            view_turns: turn.quarter_turns,
            catheter_entry: options.entry.turns_views().then(|| {
                // A view turned k quarter turns clockwise has its catheter entering through
                // the edge that 4 - k more turns bring to the bottom.
                let right = usize::from((4 - turn.quarter_turns % 4) % 4);
                EntryUse {
                    setting: options.entry.text(),
                    views_read_turned: entry_counts.read_turned,
                    views_placed_right: Some(entry_counts.kept_at.map(|kept| kept[right])),
                    view_readings: Some(entry_counts.readings),
                    pairs: pairs.items.len(),
                }
            }),
            mask_averaging: model.mask_averaging,
            estimator: estimator.name().into(),
            catheter: options.catheter.clone(),
            header_error: options.header_error,
            pairs_at_other_angles,
        },
        predictions,
    ))
}

/// Whether the network both segments and estimates a force (what the combined estimate needs).
fn force_head_and_masks(model: &Predictor) -> bool {
    model.spec.heads() == (true, true)
}

/// The split a combination is calibrated on when `evaluated` is evaluated: the validation split,
/// or the test split when the validation split is the one evaluated.
pub fn calibration_split(evaluated: Split) -> Split {
    match evaluated {
        Split::Val => Split::Test,
        Split::Train | Split::Test => Split::Val,
    }
}

pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    for (flag, value) in [
        ("--carm-angle-error", args.carm_angle_error),
        ("--carm-distance-error", args.carm_distance_error),
        ("--carm-isocentre-error", args.carm_isocentre_error),
    ] {
        anyhow::ensure!(
            value.is_finite() && value >= 0.0,
            "{flag} must be a bound of 0 or more, not {value}"
        );
    }
    let device = args.backend.device()?;
    let run = args.run.as_ref().map(RunDir::new);
    let (mut model, data) = match (&run, &args.weights) {
        (Some(run), _) => {
            let data = match &args.data {
                Some(d) => d.clone(),
                None => run.read_info()?.data,
            };
            (load_run(run, &device)?, data)
        }
        (None, Some(weights)) => (
            load_weights(weights, args.size.map(ImageSize::square), &device)?,
            args.data.clone().context("--weights needs --data")?,
        ),
        (None, None) => anyhow::bail!("give --run or --weights"),
    };
    let weights_file = match (&run, &args.weights) {
        (Some(run), _) => run.model_file(),
        (_, Some(weights)) => weights.clone(),
        (None, None) => unreachable!("a model was loaded"),
    };
    read_views_as_recorded(&mut model, args.mask_averaging, &weights_file)?;
    let (evaluation, predictions) = evaluate(
        &model,
        &data,
        args.split,
        &device,
        args.batch_size,
        &EvalOptions {
            physics_check: !args.no_physics,
            calibration: args.calibration.clone(),
            masks: args.masks.clone(),
            view_turns: args.turn_views,
            entry: args.catheter_entry,
            catheter: if args.oracle {
                None
            } else {
                Some(CatalogueCatheter::find(&args.catheter)?)
            },
            header_error: HeaderError {
                angle_deg: args.carm_angle_error,
                distance_mm: args.carm_distance_error,
                isocentre_mm: args.carm_isocentre_error,
            },
        },
    )?;
    // A run keeps its tables and predictions (of its views as they are, read as trained);
    // weights on their own, and turned views, are only printed.
    if let Some(run) = run
        .as_ref()
        .filter(|_| evaluation.view_turns == 0 && evaluation.catheter_entry.is_none())
    {
        let write = |path: PathBuf, bytes: &[u8]| {
            std::fs::write(&path, bytes)
                .with_context(|| format!("cannot write '{}'", path.display()))
        };
        let [json, md] = run.eval_files(args.split);
        write(json, &serde_json::to_vec_pretty(&evaluation)?)?;
        write(md, markdown(&evaluation).as_bytes())?;
        write(
            run.predictions_file(args.split),
            predictions_csv(&predictions, &evaluation.estimator).as_bytes(),
        )?;
    }
    if args.record {
        record_facts(&model, &evaluation, &predictions, args, &weights_file)?;
    }
    if let Some(path) = &args.predictions {
        std::fs::write(path, predictions_csv(&predictions, &evaluation.estimator))
            .with_context(|| format!("cannot write '{}'", path.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&evaluation)?);
    } else {
        print!("{}", markdown(&evaluation));
    }
    Ok(())
}
