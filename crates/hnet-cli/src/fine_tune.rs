//! `hnet fine-tune`: the page's "Fine-tune on my pairs", natively, with the same code
//! ([`hnet_model::fine_tune`]): a few labelled pairs of a dataset, every fifth held back, the
//! encoders frozen, early stopping on the held-back loss; the best epoch's weights written. For
//! measuring what the page's fine-tune does (docs/results.md) and for fine-tuning on a machine
//! without a browser; `hnet train --init` is the full training recipe from a weights file.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use burn::tensor::Device;
use hnet_model::fine_tune::{FineTune, FineTuneSettings, HeldBackScores, TrainingPair};
use hnet_twin::dataset::{Dataset, Split, SquareSymmetry};
use hnet_twin::model_facts::{FineTuneRecord, fine_tuned_provenance, recorded_name};

use crate::backend::BackendChoice;
use crate::data::StereoSplit;
use crate::evaluation::parse_split;

/// `hnet fine-tune` arguments.
#[derive(clap::Args, Debug)]
pub struct FineTuneArgs {
    /// The weights file to start from (an H-Net).
    #[arg(long)]
    weights: PathBuf,
    /// Dataset folder whose pairs train (every fifth held back to score and stop on).
    #[arg(long)]
    data: PathBuf,
    /// Which split's pairs: `train`, `val` or `test`.
    #[arg(long, value_parser = parse_split, default_value = "train")]
    split: Split,
    /// Use the first N pairs of the split (all when absent).
    #[arg(long)]
    pairs: Option<usize>,
    /// Turn both views of every pair this many quarter turns clockwise first (0-3): a catheter
    /// entering through another edge, as `hnet eval --turn-views` reads it.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=3))]
    turn_views: u8,
    /// Most epochs (the page's default: 12).
    #[arg(long)]
    epochs: Option<usize>,
    /// Learn the masks only: leave the pairs' force labels out.
    #[arg(long)]
    masks_only: bool,
    /// RMSprop's learning rate (the page's default when absent).
    #[arg(long)]
    learning_rate: Option<f64>,
    /// Train the encoders too (the page freezes them).
    #[arg(long)]
    train_encoders: bool,
    /// Seed of the order the pairs are visited in (the page's: 0); a run-to-run spread
    /// comes from several.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Most epochs without a better held-back loss (the page's default when absent).
    #[arg(long)]
    patience: Option<usize>,
    /// Rehearse on the first `--replay-pairs` training pairs of this dataset too, never held
    /// back, as they are (not turned) and with their force labels unless
    /// `--replay-masks-only`: pairs of the domain the weights were trained
    /// on, so that fine-tuning on another does not make them forget it.
    #[arg(long)]
    replay: Option<PathBuf>,
    /// Pairs of `--replay` to rehearse on.
    #[arg(long, default_value_t = 20)]
    replay_pairs: usize,
    /// Rehearse the masks only: leave the rehearsed pairs' force labels out.
    #[arg(long)]
    replay_masks_only: bool,
    /// Split each step between this many replicas, their gradients averaged, as the page's
    /// tuning workers (one per core, at most the batch of 2) do: the same numbers as the page on
    /// a machine with that many cores. The replicas run one after another here.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    replicas: u64,
    /// Share of the starting weights in the network scored and kept: each epoch's weights moved
    /// this far back towards the starting ones (0 keeps the trained weights; the page's 0.15
    /// when left out).
    #[arg(long)]
    start_share: Option<f64>,
    /// Where to compute (the page fine-tunes on WebGPU when its start-up check passed, on its
    /// CPU workers otherwise).
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// The weights file to write (the best epoch's network, as kept).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &FineTuneArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let weights = std::fs::read(&args.weights)
        .with_context(|| format!("cannot read weights file '{}'", args.weights.display()))?;
    let source = recorded_name(&args.weights);
    let header = hnet_model::weights::read_header(&weights, &source)?;
    let size = hnet_model::architectures::ModelSpec::from_settings_json(
        &header.architecture,
        &header.config_json,
    )
    .ok()
    .and_then(|spec| match spec {
        hnet_model::architectures::ModelSpec::Hnet(c) => Some(c.image_size),
        _ => None,
    })
    .with_context(|| format!("'{source}' does not hold an H-Net"))?;
    let dataset = Dataset::open(&args.data)?;
    let turn = SquareSymmetry {
        quarter_turns: args.turn_views % 4,
        mirrored: false,
    };
    let split = StereoSplit::load_turned(&dataset, args.split, size, args.pairs, turn)?;
    let pair = |item: &crate::data::StereoItem, with_force: bool| TrainingPair {
        view_a: item.view_a.to_vec(),
        view_b: item.view_b.to_vec(),
        mask_a: item.mask_a.to_vec(),
        mask_b: item.mask_b.to_vec(),
        force_n: with_force.then_some(item.force_n),
    };
    let pairs: Vec<TrainingPair> = split
        .items
        .iter()
        .map(|item| pair(item, !args.masks_only))
        .collect();
    let rehearsed: Vec<TrainingPair> = match &args.replay {
        Some(replay) => StereoSplit::load_turned(
            &Dataset::open(replay)?,
            Split::Train,
            size,
            Some(args.replay_pairs),
            SquareSymmetry::IDENTITY,
        )?
        .items
        .iter()
        .map(|item| pair(item, !args.replay_masks_only))
        .collect(),
        None => Vec::new(),
    };
    let defaults = FineTuneSettings::default();
    let settings = FineTuneSettings {
        max_epochs: args.epochs.unwrap_or(defaults.max_epochs),
        learning_rate: args.learning_rate.unwrap_or(defaults.learning_rate),
        patience: args.patience.unwrap_or(defaults.patience),
        freeze_encoders: !args.train_encoders,
        seed: args.seed,
        replicas: args.replicas as usize,
        start_share: args.start_share.unwrap_or(defaults.start_share),
        ..defaults
    };
    let count = pairs.len();
    let device: Device = args.backend.device()?;
    let mut run =
        FineTune::new(&weights, &source, pairs, settings, &device)?.with_rehearsal(rehearsed)?;
    let (train, held) = run.split();
    let before = run.score()?;
    eprintln!(
        "{count} pairs of {} ({train} trained on, {held} held back), learning rate {}, {} \
         replica(s), encoders {}, {} of the starting weights kept; before: {}",
        args.data.display(),
        settings.learning_rate,
        run.replicas(),
        if settings.freeze_encoders {
            "frozen"
        } else {
            "trained"
        },
        settings.start_share,
        scores(&before)
    );
    let mut best = None;
    while run.finished().is_none() {
        if let Some(report) = run.step()? {
            eprintln!(
                "epoch {}: training loss {:.4}; held back: {}{} ({:.0} s)",
                report.epoch,
                report.train_loss,
                scores(&report.held_back),
                if report.best { ", best" } else { "" },
                started.elapsed().as_secs_f64()
            );
            if report.best {
                best = Some(report);
            }
        }
    }
    let Some(best) = best else {
        anyhow::bail!(
            "no epoch improved on the held-back pairs ({:?}): nothing written",
            run.finished()
        );
    };
    let command = crate::command_line();
    let provenance = fine_tuned_provenance(
        &header.provenance,
        FineTuneRecord {
            command: &command,
            from: &source,
            on: format!(
                "{count} pairs of {} ({} split, {train} trained on, {held} held back)",
                recorded_name(&args.data),
                args.split.name()
            ),
            best_epoch: best.epoch,
            before: before.to_string(),
            after: best.held_back.to_string(),
        },
    );
    let bytes = run
        .best_weights(&provenance)?
        .context("no best epoch to write")?;
    hnet_twin::dataset::files::write_atomically(&args.out, &bytes)
        .with_context(|| format!("cannot write '{}'", args.out.display()))?;
    eprintln!(
        "best epoch {} ({}); weights in {} after {:.0} s",
        best.epoch,
        run.finished()
            .map_or_else(|| "not finished".to_string(), |why| why.to_string()),
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Held-back scores in words, with their loss.
fn scores(s: &HeldBackScores) -> String {
    format!("{s}, loss {:.4}", s.loss)
}
