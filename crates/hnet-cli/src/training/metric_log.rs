//! How `hnet train` writes its metric logs: the files and lines burn-train's `FileMetricLogger`
//! writes (`<run>/<split>/epoch-<n>/<metric>.log`, one serialized entry per line, which
//! [`crate::run_dir::RunDir::epoch_metrics`] and burn-train's early stopping read back), but a
//! write that fails (a full disk, a file in the way) is kept as a message naming the file in
//! the run's [`WriteFailure`] instead of a panic in burn-train's logger thread. Writing stops
//! there; the stopping rule ends the run after that epoch and `hnet train` reports it with the
//! epoch `--resume` continues from.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use burn::train::logger::MetricLogger;
use burn::train::metric::store::{EpochSummary, MetricsUpdate, Split};
use burn::train::metric::{MetricDefinition, MetricEntry, MetricId, NumericEntry};

use super::checkpoints::WriteFailure;

/// The prefix of an epoch's folder of logs (burn-train's).
const EPOCH_PREFIX: &str = "epoch-";

/// A run's metric logs (see the module's documentation).
pub struct RunMetricLogger {
    root: PathBuf,
    definitions: HashMap<MetricId, MetricDefinition>,
    /// The open log files of the current epoch, by path.
    files: HashMap<PathBuf, BufWriter<File>>,
    epoch: Option<usize>,
    failure: WriteFailure,
}

impl RunMetricLogger {
    /// The logs of the run folder `root`, reporting a failed write to `failure`.
    pub fn new(root: &Path, failure: &WriteFailure) -> Self {
        Self {
            root: root.to_path_buf(),
            definitions: HashMap::new(),
            files: HashMap::new(),
            epoch: None,
            failure: failure.clone(),
        }
    }

    /// The log of metric `name` for `epoch` of `split`.
    fn file(&self, name: &str, epoch: usize, split: &Split) -> PathBuf {
        let split_dir = match split {
            Split::Test(Some(tag)) => self
                .root
                .join(split.to_string())
                .join(tag.trim().replace(' ', "-").to_lowercase()),
            _ => self.root.join(split.to_string()),
        };
        split_dir
            .join(format!("{EPOCH_PREFIX}{epoch}"))
            .join(format!("{}.log", name.replace(' ', "_")))
    }

    /// Appends `line` to `path`'s log (created, replacing an older one, when first written in
    /// this epoch).
    fn write(&mut self, path: PathBuf, line: &str) -> std::io::Result<()> {
        if !self.files.contains_key(&path) {
            if let Some(dir) = path.parent() {
                std::fs::create_dir_all(dir)?;
            }
            let file = File::create(&path)?;
            self.files.insert(path.clone(), BufWriter::new(file));
        }
        let file = self.files.get_mut(&path).expect("opened above");
        writeln!(file, "{line}")
    }

    /// Writes out every open log (they stay open); the first failure is kept.
    fn flush_open(&mut self) {
        let failures: Vec<String> = self
            .files
            .iter_mut()
            .filter_map(|(path, file)| {
                file.flush()
                    .err()
                    .map(|e| format!("cannot write metric log '{}': {e}", path.display()))
            })
            .collect();
        for failure in failures {
            self.failure.note(failure);
        }
    }

    /// Writes out and closes every open log (a split of an epoch has ended).
    fn close_all(&mut self) {
        self.flush_open();
        self.files.clear();
    }

    fn log_entry(&mut self, entry: &MetricEntry, epoch: usize, split: &Split) {
        if entry.serialized_entry.is_not_available() {
            return;
        }
        let Some(name) = self
            .definitions
            .get(&entry.metric_id)
            .map(|d| d.name.to_string())
        else {
            return;
        };
        let path = self.file(&name, epoch, split);
        if let Err(e) = self.write(path.clone(), &entry.serialized_entry.serialized) {
            self.failure
                .note(format!("cannot write metric log '{}': {e}", path.display()));
        }
    }
}

impl MetricLogger for RunMetricLogger {
    fn log(&mut self, update: MetricsUpdate, epoch: usize, split: &Split) {
        if self.epoch != Some(epoch) {
            self.close_all();
            self.epoch = Some(epoch);
        }
        // After a failed write nothing more is written: the run stops after this epoch.
        if self.failure.get().is_some() {
            return;
        }
        let entries = update
            .entries
            .iter()
            .chain(update.entries_numeric.iter().map(|n| &n.entry));
        for entry in entries {
            self.log_entry(entry, epoch, split);
        }
    }

    fn read_numeric(
        &mut self,
        name: &str,
        epoch: usize,
        split: &Split,
    ) -> Result<Vec<NumericEntry>, String> {
        self.flush_open();
        let text = std::fs::read_to_string(self.file(name, epoch, split)).unwrap_or_default();
        text.lines()
            .filter(|line| !line.is_empty())
            .map(NumericEntry::deserialize)
            .collect()
    }

    fn log_metric_definition(&mut self, definition: MetricDefinition) {
        self.definitions
            .insert(definition.metric_id.clone(), definition);
    }

    fn log_epoch_summary(&mut self, _summary: EpochSummary) {
        self.close_all();
    }
}

impl Drop for RunMetricLogger {
    fn drop(&mut self) {
        self.close_all();
    }
}
