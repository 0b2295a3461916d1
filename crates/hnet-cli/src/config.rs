//! The training settings (`configs/*.json`, and `config.json` in a run folder): the network,
//! the input size, the loss weights and the optimiser's schedule. Read by `hnet train`, and by
//! `hnet eval` for the input size a run was trained at.

use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow, bail};
use hnet_model::HNetLossConfig;
use hnet_model::architectures::ModelSpec;
use hnet_model::weights::ConfigProblem;
use hnet_twin::dataset::label_origin::LabelFilter;
use hnet_units::{ImageSize, MAX_IMAGE_SIDE};
use serde::{Deserialize, Serialize};

use crate::data::twin_stream::TwinStreamConfig;

/// The most threads decoding or simulating batches.
pub const MAX_WORKERS: usize = 256;

/// How the learning rates change over a run.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LearningRateSchedule {
    /// The configured rates throughout (the paper's).
    #[default]
    Constant,
    /// Cosine annealing from each configured rate down to `final_factor` times it at the last
    /// step of the last epoch.
    Cosine {
        /// The final rate as a fraction of the starting one.
        final_factor: f64,
    },
}

/// Everything that defines a training run (`config.json` in the run folder).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingConfig {
    /// A short name for the settings (`paper`, `cpu`, ...).
    pub name: String,
    /// The network and its settings.
    pub model: ModelSpec,
    /// Input size in pixels; images are resized to it.
    pub image_size: ImageSize,
    /// Loss weights β1, β2, β3 (eq. 7).
    pub loss: HNetLossConfig,
    /// RMSprop learning rate (the paper: 1e-4).
    pub learning_rate: f64,
    /// Learning rate of H-Net's force head (its dense layers), when it differs from
    /// `learning_rate`. The head reads globally pooled, all-positive features that vary little
    /// between pairs, so RMSprop's nearly sign-sized steps at a large rate push whole hidden units
    /// below zero for every input at once, where they stay (dead ReLUs). A smaller rate for the
    /// head alone lets the encoder-decoder learn fast without losing the head.
    #[serde(default)]
    pub force_head_learning_rate: Option<f64>,
    /// Train H-Net's force head on standardised forces: the train split's per-axis mean and
    /// standard deviation (from its manifest) are put in the network's settings, so that its
    /// outputs stay in newtons, and the force loss becomes the MSE of standardised forces. The
    /// run's `config.json` records the statistics used.
    #[serde(default)]
    pub standardise_force: bool,
    /// How the learning rates change over the run.
    #[serde(default)]
    pub schedule: LearningRateSchedule,
    /// RMSprop smoothing constant (Keras' default `rho`, 0.9).
    pub rmsprop_alpha: f32,
    /// RMSprop momentum (Keras' default, 0).
    pub rmsprop_momentum: f32,
    /// RMSprop epsilon (Keras' default, 1e-7).
    pub rmsprop_epsilon: f32,
    /// Pairs per batch.
    pub batch_size: usize,
    /// Most epochs.
    pub epochs: usize,
    /// Stop when the validation loss has not improved for this many epochs.
    pub patience: usize,
    /// Seed of the weights' initialisation and of the shuffling.
    pub seed: u64,
    /// Use at most this many training pairs (all when absent).
    pub max_train_samples: Option<usize>,
    /// Use at most this many validation pairs (all when absent).
    pub max_valid_samples: Option<usize>,
    /// Threads decoding batches (or simulating them, with `stream`).
    pub num_workers: usize,
    /// Most memory the training split may take decoded, MiB ([`DEFAULT_MAX_MEMORY_MIB`] when
    /// absent): a larger split is read from disk batch by batch (PNGs decoded every epoch,
    /// memory independent of the number of pairs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_memory_mib: Option<usize>,
    /// Train on pairs the twin simulates during training, fresh every epoch, instead of the
    /// dataset's train split (which then only gives the force statistics); validation stays
    /// the dataset's val split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stream: Option<TwinStreamConfig>,
    /// Start from the network in this weights file instead of a random initialisation (a
    /// recipe's next stage): it must hold the config's network, its force statistics included;
    /// an H-Net may have been trained at another input size (its parameters do not depend on
    /// it). `hnet train --init FILE` sets it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_weights: Option<PathBuf>,
    /// The force labels the force head learns from, by where they came from
    /// ([`hnet_twin::dataset::label_origin`]): `all`, or origins separated by commas (`measured,typed`).
    /// Every origin but a model's estimates when absent, so that a network never learns its
    /// own guesses unless asked to. A pair whose label is left out still trains the masks.
    /// `hnet train --labels` sets it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_labels: Option<String>,
}

impl TrainingConfig {
    /// The force labels to learn from ([`TrainingConfig::force_labels`]).
    pub fn label_filter(&self) -> anyhow::Result<LabelFilter> {
        match &self.force_labels {
            None => Ok(LabelFilter::not_estimates()),
            Some(text) => LabelFilter::parse(text)
                .map_err(|e| anyhow!("`force_labels` = `{text}`: {e}, or `all`")),
        }
    }
}

/// The training split's memory budget when a config sets none, MiB.
pub const DEFAULT_MAX_MEMORY_MIB: usize = 2048;

impl TrainingConfig {
    /// Checks that the settings describe a trainable run, before anything is loaded or built:
    /// every layer count and size within bounds (so that nothing absurd is ever allocated),
    /// the image size one the network can halve.
    pub fn check(&self) -> anyhow::Result<()> {
        self.label_filter()?;
        // The baselines: the same bounds as a weights file's settings.
        self.model
            .check_layer_counts()
            .map_err(|problem| match problem {
                ConfigProblem::OutOfRange(name, value, range) => anyhow!(
                    "`model.{name}` = {value} is outside {range} for {}",
                    self.model.name()
                ),
                other => anyhow!("model: {other}"),
            })?;
        if let ModelSpec::Hnet(c) = &self.model {
            // The bounds the baselines have (its layers are built from these counts), then
            // H-Net's own rules (an image size it can halve `depth` times).
            let bounds = [
                ("in_channels", c.in_channels, 3, 3, "3 (the views are RGB)"),
                ("filters", c.filters, 1, 4096, "1..=4096"),
                ("depth", c.depth, 1, 16, "1..=16"),
                (
                    "force_hidden[0]",
                    c.force_hidden[0],
                    1,
                    1 << 16,
                    "1..=65536",
                ),
                (
                    "force_hidden[1]",
                    c.force_hidden[1],
                    1,
                    1 << 16,
                    "1..=65536",
                ),
            ];
            for (name, value, low, high, range) in bounds {
                if !(low..=high).contains(&value) {
                    bail!("`model.{name}` = {value} is outside {range} for hnet");
                }
            }
            c.validate().map_err(|e| anyhow!("model (hnet): {e}"))?;
        }
        let ImageSize { width, height } = self.image_size;
        if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
            bail!(
                "`image_size` {} is larger than {MAX_IMAGE_SIDE}×{MAX_IMAGE_SIDE} pixels",
                self.image_size
            );
        }
        let multiple = self.model.size_multiple();
        if [width, height].iter().any(|s| *s == 0 || s % multiple != 0) {
            bail!(
                "image size {} (width×height) must be a positive multiple of {multiple} for {}",
                self.image_size,
                self.model
            );
        }
        if let ModelSpec::Hnet(c) = &self.model
            && c.image_size != self.image_size
        {
            bail!(
                "the H-Net config's image_size {} differs from the training image_size {}",
                c.image_size,
                self.image_size
            );
        }
        if self.batch_size == 0 || self.epochs == 0 {
            bail!("batch_size and epochs must be at least 1");
        }
        if self.num_workers > MAX_WORKERS {
            bail!(
                "`num_workers` = {} is more than {MAX_WORKERS} threads",
                self.num_workers
            );
        }
        if let Some(stream) = &self.stream {
            stream.check()?;
        }
        Ok(())
    }

    /// Reads a config file (JSON).
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read training config '{}'", path.display()))?;
        let config: Self = serde_json::from_str(&text)
            .with_context(|| format!("'{}' is not a valid training config", path.display()))?;
        config
            .check()
            .with_context(|| format!("training config '{}'", path.display()))?;
        Ok(config)
    }
}

/// The checked-in settings, by name.
pub fn builtin_config(name: &str) -> Option<TrainingConfig> {
    let text = match name {
        "cpu" => include_str!("../../../configs/cpu.json"),
        "paper" => include_str!("../../../configs/paper.json"),
        _ => return None,
    };
    Some(serde_json::from_str(text).expect("the checked-in configs parse"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_checked_in_config_loads() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
        let names_in = |dir: &Path| {
            let mut names = Vec::new();
            for entry in std::fs::read_dir(dir).unwrap() {
                let path = entry.unwrap().path();
                if path.extension().is_some_and(|e| e == "json") {
                    let config = TrainingConfig::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
                    names.push(config.name);
                }
            }
            names.sort();
            names
        };
        // The experiments of docs/results.md too.
        assert_eq!(
            names_in(&dir.join("experiments")),
            [
                "both-grids-224",
                "force-128-any-pose",
                "force-128-masks-any-pose",
                "force-128-off-bench-any-pose",
                "force-128-off-bench-long",
                "force-224-any-pose",
                "force-224-sideways",
                "force-224-turned",
                "imaging-224",
                "outline-224",
                "outline-224-control",
                "random-grid-224",
            ]
        );
        let names = names_in(&dir);
        assert_eq!(
            names,
            [
                "cpu",
                "cpu-ynet",
                "force-128",
                "force-128-masks",
                "force-128-off-bench",
                "force-224",
                "paper",
                "paper-bench-128",
                "paper-bench-ynet-128"
            ]
        );
    }
}
