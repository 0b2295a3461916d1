//! The network a command reads pairs with: loaded from a weights file or a run folder, and run
//! over a dataset's pairs in batches. The inference itself is
//! [`hnet_model::predictor::Predictor`]'s; this module only reads files and names the command's
//! flags in its errors.

use std::path::Path;

use anyhow::Context;
use burn::tensor::Device;
use hnet_model::catheter_entry::{CatheterEntry, EntrySetting};
use hnet_model::mask_averaging::MaskAveraging;
use hnet_model::predictor::{EntryError, LoadError, PairInput, Predictor};
use hnet_twin::model_facts::ModelFacts;
use hnet_units::{ImageSize, TipForce};

use crate::data::StereoItem;
use crate::run_dir::RunDir;

/// Loads a weights file on its own. H-Net's weights record their input size; a baseline's come
/// at `size` (the command's `--size`).
pub fn load_weights(
    path: &Path,
    size: Option<ImageSize>,
    device: &Device,
) -> anyhow::Result<Predictor> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read weights file '{}'", path.display()))?;
    let source = path.display().to_string();
    Predictor::from_weights_bytes(&bytes, size, device, &source).map_err(|error| {
        let hint = match &error {
            LoadError::OtherSize { .. } => " (leave --size out)",
            LoadError::SizeUnknown { .. } | LoadError::BadSize { .. } => " (--size)",
            LoadError::Weights(_) => "",
        };
        anyhow::Error::new(error).context(format!("loading the network{hint}"))
    })
}

/// Parses `--mask-averaging` ([`MaskAveraging::name`]).
pub fn parse_mask_averaging(text: &str) -> Result<MaskAveraging, String> {
    MaskAveraging::from_name(text).map_err(|e| e.to_string())
}

/// Sets how `model`, loaded from `weights`, reads each view: `asked`, or else as its recorded
/// calibration was measured ([`ModelFacts::mask_averaging`]); reading them otherwise than a
/// recorded calibration is allowed and said. Returns the weights' facts.
pub fn read_views_as_recorded(
    model: &mut Predictor,
    asked: Option<MaskAveraging>,
    weights: &Path,
) -> anyhow::Result<ModelFacts> {
    let facts = ModelFacts::read(&model.header.provenance)
        .with_context(|| format!("weights file '{}'", weights.display()))?;
    let calibrated_with = facts.mask_averaging();
    model.mask_averaging = asked.unwrap_or(calibrated_with);
    if model.mask_averaging != calibrated_with && facts.combination().is_some() {
        eprintln!(
            "note: reading each view `{}`, while '{}' was calibrated reading them `{}`: its 90 % \
             intervals were measured on other masks",
            model.mask_averaging.name(),
            weights.display(),
            calibrated_with.name()
        );
    }
    Ok(facts)
}

/// Loads a run folder's `model.bpk`: H-Net at the size its weights record, a baseline at the
/// size its training config gives.
pub fn load_run(run: &RunDir, device: &Device) -> anyhow::Result<Predictor> {
    let path = run.model_file();
    let source = path.display().to_string();
    let loaded = std::fs::read(&path)
        .with_context(|| format!("cannot read weights file '{source}'"))
        .and_then(
            |bytes| match Predictor::from_weights_bytes(&bytes, None, device, &source) {
                Err(LoadError::SizeUnknown { .. }) => {
                    let size = run.read_config()?.image_size;
                    Ok(Predictor::from_weights_bytes(
                        &bytes,
                        Some(size),
                        device,
                        &source,
                    )?)
                }
                loaded => Ok(loaded?),
            },
        );
    loaded.with_context(|| {
        format!(
            "run folder '{}' (has `hnet train` finished?)",
            run.root().display()
        )
    })
}

/// A dataset pair as the network reads it.
fn input(item: &StereoItem) -> PairInput<'_> {
    PairInput {
        view_a: &item.view_a,
        view_b: &item.view_b,
        masks: Some([&item.mask_a, &item.mask_b]),
    }
}

/// Runs `model` on `items` in batches of `batch_size`; calls `visit` with each pair, its masks
/// (catheter probabilities of views A and B) and its force (newtons).
pub fn predict(
    model: &Predictor,
    items: &[StereoItem],
    batch_size: usize,
    device: &Device,
    mut visit: impl FnMut(&StereoItem, Option<[Vec<f32>; 2]>, Option<TipForce>),
) -> anyhow::Result<()> {
    for chunk in items.chunks(batch_size.max(1)) {
        let inputs: Vec<PairInput<'_>> = chunk.iter().map(input).collect();
        for (item, output) in chunk.iter().zip(model.predict(&inputs, device)?) {
            visit(item, output.masks, output.force);
        }
    }
    Ok(())
}

/// How [`predict_entry`]'s views were read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EntryCounts {
    /// Views A and B read turned (kept at another edge than the bottom).
    pub read_turned: [usize; 2],
    /// Views A and B kept at each edge, in [`CatheterEntry::ALL`]'s order.
    pub kept_at: [[usize; 4]; 2],
    /// Readings of views A and B the search took (one per view read once).
    pub readings: [usize; 2],
}

/// [`predict`] with each pair's views read under `entry` (the command's `--catheter-entry`):
/// see [`Predictor::predict_entry`]. Returns how the views were read.
pub fn predict_entry(
    model: &Predictor,
    items: &[StereoItem],
    batch_size: usize,
    device: &Device,
    entry: EntrySetting,
    mut visit: impl FnMut(&StereoItem, Option<[Vec<f32>; 2]>, Option<TipForce>),
) -> anyhow::Result<EntryCounts> {
    let mut counts = EntryCounts::default();
    for chunk in items.chunks(batch_size.max(1)) {
        let inputs: Vec<PairInput<'_>> = chunk.iter().map(input).collect();
        let outputs = model
            .predict_entry(&inputs, device, entry)
            .map_err(|error| match error {
                EntryError::NoMasks(name) => {
                    anyhow::anyhow!("--catheter-entry reads masks; a `{name}` network gives none")
                }
                EntryError::NotSquare(size) => anyhow::anyhow!(
                    "--catheter-entry needs a square network; this one takes {size} images"
                ),
                EntryError::Predict(error) => anyhow::Error::new(error),
                EntryError::Turn(error) => anyhow::Error::new(error),
            })?;
        for (item, read) in chunk.iter().zip(outputs) {
            for view in 0..2 {
                let edge = read.entry[view];
                counts.read_turned[view] += usize::from(edge != CatheterEntry::Bottom);
                counts.kept_at[view][usize::from(edge.quarter_turns())] += 1;
                counts.readings[view] += read.readings[view];
            }
            visit(item, read.output.masks, read.output.force);
        }
    }
    Ok(counts)
}
