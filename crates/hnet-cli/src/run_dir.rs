//! A training run's folder: every file `hnet train` writes there and `hnet eval` and `hnet
//! report` read, named here once.
//!
//! ```text
//! RUN/config.json                       the training settings (crate::config::TrainingConfig)
//! RUN/run.json                          the dataset, the backend and the command (RunInfo)
//! RUN/model.bpk                         the best epoch's network, a weights file
//! RUN/metrics.csv                       per-epoch means of every logged metric
//! RUN/checkpoint/{model,optim,scheduler}-<epoch>.bpk      checkpoints (training/checkpoints.rs)
//! RUN/{train,valid}/epoch-<epoch>/<metric>.log            burn-train's metric logs
//! RUN/eval-<split>.{json,md}, RUN/predictions-<split>.csv `hnet eval`
//! RUN/report/                           `hnet report`'s figures
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use hnet_twin::dataset::Split;
use hnet_twin::dataset::files::write_atomically;
use serde::{Deserialize, Serialize};

use crate::config::TrainingConfig;

/// The metric every network logs: the total loss (eq. 7, or the terms a baseline has).
pub const LOSS_METRIC: &str = "Loss";

/// The parts of a burn-train checkpoint (network, optimiser, learning rate scheduler); an epoch
/// is complete when all three are there.
pub const CHECKPOINT_PARTS: [&str; 3] = ["model", "optim", "scheduler"];

/// What is saved in the run folder besides burn-train's own files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    /// The dataset folder.
    pub data: PathBuf,
    /// The backend used.
    pub backend: String,
    /// The command that started the run.
    pub command: String,
}

/// One epoch's metric means on one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EpochRow {
    /// Epoch number (from 1).
    pub epoch: usize,
    /// `train` or `valid`.
    pub split: String,
    /// Metric name (as the metric names itself, e.g. `Force MAE`) to its mean.
    pub values: BTreeMap<String, f64>,
}

/// A run folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// The run folder at `root` (which need not exist yet).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The folder itself (where burn-train writes its own files).
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The training settings.
    pub fn config_file(&self) -> PathBuf {
        self.root.join("config.json")
    }

    /// The run's [`RunInfo`].
    pub fn info_file(&self) -> PathBuf {
        self.root.join("run.json")
    }

    /// The best epoch's network.
    pub fn model_file(&self) -> PathBuf {
        self.root.join("model.bpk")
    }

    /// Per-epoch metric means.
    pub fn metrics_file(&self) -> PathBuf {
        self.root.join("metrics.csv")
    }

    /// Where burn-train keeps its checkpoints.
    pub fn checkpoint_dir(&self) -> PathBuf {
        self.root.join("checkpoint")
    }

    /// Part `part` (one of [`CHECKPOINT_PARTS`]) of epoch `epoch`'s checkpoint.
    pub fn checkpoint_file(&self, part: &str, epoch: usize) -> PathBuf {
        self.checkpoint_dir().join(format!("{part}-{epoch}.bpk"))
    }

    /// The checksum written beside a checkpoint part once it is complete
    /// (`<part>-<epoch>.bpk.crc32`): see [`Self::write_checkpoint_checksum`].
    pub fn checkpoint_checksum_file(&self, part: &str, epoch: usize) -> PathBuf {
        let mut name = self.checkpoint_file(part, epoch).into_os_string();
        name.push(".crc32");
        name.into()
    }

    /// Writes the CRC-32 and length of a checkpoint part beside it (atomically), so that a
    /// part garbled after it was written, even one that still reads as a checkpoint (burn-pack
    /// files carry no checksum of their own), is noticed by `--resume`.
    pub fn write_checkpoint_checksum(&self, part: &str, epoch: usize) -> std::io::Result<()> {
        let bytes = std::fs::read(self.checkpoint_file(part, epoch))?;
        write_atomically(
            &self.checkpoint_checksum_file(part, epoch),
            checksum_line(&bytes).as_bytes(),
        )
    }

    /// Why a checkpoint part does not match the checksum written beside it, if it does not.
    /// Parts without one (written before checksums were kept) are not checked.
    fn checkpoint_checksum_mismatch(&self, part: &str, epoch: usize) -> Option<String> {
        let recorded = std::fs::read_to_string(self.checkpoint_checksum_file(part, epoch)).ok()?;
        let bytes = match std::fs::read(self.checkpoint_file(part, epoch)) {
            Ok(bytes) => bytes,
            Err(e) => return Some(e.to_string()),
        };
        let actual = checksum_line(&bytes);
        (recorded != actual).then(|| {
            format!(
                "it does not match its checksum (recorded {}, now {})",
                recorded.trim(),
                actual.trim()
            )
        })
    }

    /// The network of epoch `epoch`'s checkpoint.
    pub fn checkpoint_model_file(&self, epoch: usize) -> PathBuf {
        self.checkpoint_file("model", epoch)
    }

    /// `hnet eval`'s tables of `split`, as JSON and Markdown.
    pub fn eval_files(&self, split: Split) -> [PathBuf; 2] {
        let stem = format!("eval-{}", split.name());
        [
            self.root.join(format!("{stem}.json")),
            self.root.join(format!("{stem}.md")),
        ]
    }

    /// `hnet eval`'s per-pair force predictions on `split`.
    pub fn predictions_file(&self, split: Split) -> PathBuf {
        self.root.join(format!("predictions-{}.csv", split.name()))
    }

    /// Where `hnet report` writes its figures by default.
    pub fn report_dir(&self) -> PathBuf {
        self.root.join("report")
    }

    /// Whether the folder is missing or empty (a new run may start there).
    pub fn is_empty(&self) -> anyhow::Result<bool> {
        Ok(!self.root.exists() || std::fs::read_dir(&self.root)?.next().is_none())
    }

    /// The training settings saved with the run.
    pub fn read_config(&self) -> anyhow::Result<TrainingConfig> {
        TrainingConfig::load(&self.config_file())
    }

    /// Saves the training settings (atomically: a failed write leaves the old file).
    pub fn write_config(&self, config: &TrainingConfig) -> anyhow::Result<()> {
        let path = self.config_file();
        write_atomically(&path, &serde_json::to_vec_pretty(config)?)
            .with_context(|| format!("cannot write '{}'", path.display()))
    }

    /// The run's dataset, backend and command.
    pub fn read_info(&self) -> anyhow::Result<RunInfo> {
        let path = self.info_file();
        let bytes =
            std::fs::read(&path).with_context(|| format!("cannot read '{}'", path.display()))?;
        serde_json::from_slice(&bytes)
            .with_context(|| format!("'{}' is not a run record", path.display()))
    }

    /// Saves the run's dataset, backend and command (atomically: `--resume` rewrites it, and a
    /// failed write must leave the old record readable).
    pub fn write_info(&self, info: &RunInfo) -> anyhow::Result<()> {
        let path = self.info_file();
        write_atomically(&path, &serde_json::to_vec_pretty(info)?)
            .with_context(|| format!("cannot write '{}'", path.display()))
    }

    /// The epochs with a complete checkpoint (model, optimiser and scheduler), in order.
    pub fn checkpoint_epochs(&self) -> Vec<usize> {
        let dir = self.checkpoint_dir();
        let mut epochs: Vec<usize> = std::fs::read_dir(&dir)
            .map(|entries| {
                entries
                    .filter_map(|e| e.ok())
                    .filter_map(|e| {
                        let name = e.file_name().to_string_lossy().into_owned();
                        name.strip_prefix("model-")?
                            .strip_suffix(".bpk")?
                            .parse()
                            .ok()
                    })
                    .filter(|epoch: &usize| {
                        CHECKPOINT_PARTS
                            .iter()
                            .all(|k| dir.join(format!("{k}-{epoch}.bpk")).is_file())
                    })
                    .collect()
            })
            .unwrap_or_default();
        epochs.sort_unstable();
        epochs
    }

    /// The last epoch whose checkpoint reads back whole, for `--resume`. A later one that cannot
    /// be read (cut short or garbled by a fault after it was written) is set aside, each part
    /// renamed to `*.bpk.damaged`, with a warning naming the file, and the one before it is taken.
    pub fn last_readable_checkpoint(&self) -> anyhow::Result<Option<usize>> {
        for epoch in self.checkpoint_epochs().into_iter().rev() {
            let unreadable = CHECKPOINT_PARTS.iter().find_map(|part| {
                let file = self.checkpoint_file(part, epoch);
                self.checkpoint_checksum_mismatch(part, epoch)
                    .or_else(|| {
                        burn::store::ModuleRecord::load(&file)
                            .err()
                            .map(|e| e.to_string())
                    })
                    .map(|e| (file, e))
            });
            let Some((file, error)) = unreadable else {
                return Ok(Some(epoch));
            };
            eprintln!(
                "warning: checkpoint '{}' cannot be read ({error}): epoch {epoch}'s checkpoint is \
                 set aside as *.bpk.damaged and an earlier one is used",
                file.display()
            );
            self.set_aside(epoch, "damaged")?;
        }
        Ok(None)
    }

    /// Sets aside epoch `epoch`'s checkpoint (each part renamed to `*.bpk.non-finite`, kept for
    /// inspection), so that `--resume` continues from the last checkpoint before it; whether it
    /// had one (an epoch stopped at a diverged step has none).
    pub fn set_aside_checkpoint(&self, epoch: usize) -> anyhow::Result<bool> {
        self.set_aside(epoch, "non-finite")
    }

    /// Renames each part of epoch `epoch`'s checkpoint to `*.bpk.<why>`; whether it had any.
    fn set_aside(&self, epoch: usize, why: &str) -> anyhow::Result<bool> {
        let dir = self.checkpoint_dir();
        let mut any = false;
        for part in CHECKPOINT_PARTS {
            let file = self.checkpoint_file(part, epoch);
            if file.is_file() {
                let aside = dir.join(format!("{part}-{epoch}.bpk.{why}"));
                std::fs::rename(&file, &aside)
                    .with_context(|| format!("cannot set aside '{}'", file.display()))?;
                any = true;
            }
            let checksum = self.checkpoint_checksum_file(part, epoch);
            if checksum.is_file() {
                let mut aside = checksum.clone().into_os_string();
                aside.push(format!(".{why}"));
                std::fs::rename(&checksum, &aside)
                    .with_context(|| format!("cannot set aside '{}'", checksum.display()))?;
            }
        }
        Ok(any)
    }

    /// Per-epoch means of every logged metric, from burn-train's logs, by epoch then split.
    pub fn epoch_metrics(&self) -> anyhow::Result<Vec<EpochRow>> {
        let mut rows = Vec::new();
        for split in ["train", "valid"] {
            let Ok(entries) = std::fs::read_dir(self.root.join(split)) else {
                continue;
            };
            for entry in entries.filter_map(|e| e.ok()) {
                let name = entry.file_name().to_string_lossy().into_owned();
                let Some(epoch) = name
                    .strip_prefix("epoch-")
                    .and_then(|e| e.parse::<usize>().ok())
                else {
                    continue;
                };
                let mut values = BTreeMap::new();
                let epoch_dir = entry.path();
                let files = std::fs::read_dir(&epoch_dir)
                    .with_context(|| format!("cannot list '{}'", epoch_dir.display()))?;
                for file in files.filter_map(|e| e.ok()) {
                    let file_name = file.file_name().to_string_lossy().into_owned();
                    let Some(metric) = metric_of_log_file(&file_name) else {
                        continue;
                    };
                    let log = std::fs::read_to_string(file.path())
                        .with_context(|| format!("cannot read '{}'", file.path().display()))?;
                    if let Some(mean) = weighted_mean(&log) {
                        values.insert(metric, mean);
                    }
                }
                rows.push(EpochRow {
                    epoch,
                    split: split.to_string(),
                    values,
                });
            }
        }
        rows.sort_by(|a, b| (a.epoch, &a.split).cmp(&(b.epoch, &b.split)));
        Ok(rows)
    }
}

/// A metric's name as burn-train writes it in file names: spaces made underscores (`Force MAE`
/// -> `Force_MAE`, its log `Force_MAE.log`); also the metric's column in `metrics.csv`.
pub fn log_name(metric: &str) -> String {
    metric.replace(' ', "_")
}

/// The metric a burn-train log file holds: burn-train names the file after the metric with its
/// spaces made underscores (`Force MAE` -> `Force_MAE.log`); our metric names have no
/// underscores, so this gives the name back.
fn metric_of_log_file(file_name: &str) -> Option<String> {
    file_name
        .strip_suffix(".log")
        .map(|stem| stem.replace('_', " "))
}

/// Mean of a burn-train metric log (`value,count` per line), weighted by count. Non-finite
/// values are kept: a diverged run must show in the curves.
fn weighted_mean(log: &str) -> Option<f64> {
    let (mut sum, mut count) = (0.0, 0.0);
    for line in log.lines() {
        let mut parts = line.split(',');
        let Some(Ok(value)) = parts.next().map(str::parse::<f64>) else {
            continue;
        };
        let weight = parts
            .next()
            .and_then(|c| c.parse::<f64>().ok())
            .unwrap_or(1.0);
        sum += value * weight;
        count += weight;
    }
    (count > 0.0).then(|| sum / count)
}

/// A checkpoint file's checksum record: its CRC-32 (`crc32fast`, SIMD-accelerated; enough to
/// notice corruption, not meant against tampering) and its length in bytes.
fn checksum_line(bytes: &[u8]) -> String {
    format!(
        "crc32 {:08x} bytes {}\n",
        crc32fast::hash(bytes),
        bytes.len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logs_name_their_metric_and_average_by_count() {
        assert_eq!(
            metric_of_log_file("Force_MAE.log").as_deref(),
            Some("Force MAE")
        );
        assert_eq!(metric_of_log_file("Loss.log").as_deref(), Some("Loss"));
        assert_eq!(log_name("Force MAE"), "Force_MAE");
        assert_eq!(metric_of_log_file("notes.txt"), None);
        assert_eq!(weighted_mean("1,1\n4,2\n"), Some(3.0));
        assert!(weighted_mean("NaN,8\n1,8\n").unwrap().is_nan());
        assert_eq!(weighted_mean(""), None);
    }

    #[test]
    fn checkpoints_count_only_when_complete() {
        let root = std::env::temp_dir().join(format!("hnet-run-dir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let run = RunDir::new(&root);
        assert!(run.is_empty().unwrap());
        std::fs::create_dir_all(root.join("checkpoint")).unwrap();
        for (part, epoch) in [("model", 1), ("optim", 1), ("scheduler", 1), ("model", 2)] {
            std::fs::write(root.join(format!("checkpoint/{part}-{epoch}.bpk")), b"").unwrap();
        }
        assert_eq!(run.checkpoint_epochs(), vec![1]);
        assert_eq!(
            run.checkpoint_model_file(2),
            root.join("checkpoint/model-2.bpk")
        );
        std::fs::remove_dir_all(root).ok();
    }
}
