//! How `hnet train` keeps its checkpoints, so that a full disk or an unwritable run folder never
//! costs the last complete one:
//!
//! - each part of an epoch's checkpoint (network, optimiser, scheduler: [`CHECKPOINT_PARTS`]) is
//!   written by burn-pack's `Writer::write_to_file`, which writes a temporary file beside the
//!   target (`model-3.bpk.<pid>-<n>.tmp`), syncs it, renames it over the target and removes it
//!   on failure: a part on disk is whole, or absent;
//! - an older epoch's part is deleted (burn-train's strategy keeps the last two epochs and the
//!   best one) only once a later epoch's checkpoint is complete on disk, so a failed write of
//!   epoch N, even one noticed late, never leaves the run without a complete checkpoint;
//! - beside each part, once written, its CRC-32 and length (`*.bpk.crc32`), which `--resume`
//!   checks: burn-pack files carry no checksum, and a part garbled later may still load;
//! - the first write that fails is kept as a message naming the file ([`WriteFailure`]); the
//!   learner stops, and `hnet train` reports it with the epoch `--resume` continues from.
//!
//! burn-train's own `FileCheckpointer` writes the same files, but deletes old epochs whatever
//! happened to the new one, and its errors do not name the file.

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

use burn::store::RecordError;
use burn::train::checkpoint::{Checkpoint, Checkpointer, CheckpointerError};

use crate::run_dir::{CHECKPOINT_PARTS, RunDir};

/// The first write to the run folder that failed (a checkpoint or a metric log), as a message
/// naming the file; shared by the three parts' checkpointers (each on its own thread), the
/// metric logger, the stopping rule and the training loop.
#[derive(Debug, Clone, Default)]
pub struct WriteFailure(Arc<Mutex<Option<String>>>);

impl WriteFailure {
    /// The failure, if a write failed.
    pub fn get(&self) -> Option<String> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Keeps `message` unless an earlier failure is kept already (later ones are most likely
    /// its consequences).
    pub fn note(&self, message: String) {
        let mut slot = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        slot.get_or_insert(message);
    }

    /// [`Self::note`], giving the message back as burn-train's error.
    fn record(&self, message: String) -> CheckpointerError {
        self.note(message.clone());
        CheckpointerError::IOError(std::io::Error::other(message))
    }
}

/// One part's checkpoints in a run folder (see the module's documentation).
pub struct RunCheckpointer {
    run: RunDir,
    part: &'static str,
    failure: WriteFailure,
}

impl RunCheckpointer {
    /// The model, optimiser and scheduler checkpointers of `run`, reporting to `failure`.
    pub fn for_run(run: &RunDir, failure: &WriteFailure) -> [Self; 3] {
        CHECKPOINT_PARTS.map(|part| Self {
            run: run.clone(),
            part,
            failure: failure.clone(),
        })
    }

    fn failed(&self, doing: &str, file: &Path, cause: impl std::fmt::Display) -> CheckpointerError {
        self.failure.record(format!(
            "cannot {doing} checkpoint '{}': {cause}",
            file.display()
        ))
    }
}

/// burn's error without its layers of prefixes (`Record error: Record I/O error: I/O error:`):
/// burn-pack's own message, which names the file it was writing.
fn cause(error: CheckpointerError) -> String {
    match error {
        CheckpointerError::Record(RecordError::Io(message)) => message
            .strip_prefix("I/O error: ")
            .unwrap_or(&message)
            .to_string(),
        CheckpointerError::Record(error) => error.to_string(),
        CheckpointerError::IOError(error) => error.to_string(),
        CheckpointerError::Unknown(message) => message,
    }
}

impl<R: Checkpoint> Checkpointer<R> for RunCheckpointer {
    fn save(&self, epoch: usize, record: R) -> Result<(), CheckpointerError> {
        let file = self.run.checkpoint_file(self.part, epoch);
        let dir = self.run.checkpoint_dir();
        std::fs::create_dir_all(&dir).map_err(|e| self.failed("write", &file, e))?;
        record
            .save(file.clone())
            .map_err(|e| self.failed("write", &file, cause(e)))?;
        self.run
            .write_checkpoint_checksum(self.part, epoch)
            .map_err(|e| {
                let checksum = self.run.checkpoint_checksum_file(self.part, epoch);
                self.failed("write", &checksum, e)
            })
    }

    fn delete(&self, epoch: usize) -> Result<(), CheckpointerError> {
        // Only once a later epoch is complete: if this epoch's is the last complete checkpoint
        // (a later write failed or is not finished), it stays, and a later delete of another
        // epoch does not come back for it (burn-train asks once), which costs disk space only
        // after a failure.
        if !self.run.checkpoint_epochs().iter().any(|&e| e > epoch) {
            return Ok(());
        }
        for file in [
            self.run.checkpoint_file(self.part, epoch),
            self.run.checkpoint_checksum_file(self.part, epoch),
        ] {
            match std::fs::remove_file(&file) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(self.failed("delete", &file, e)),
            }
        }
        Ok(())
    }

    fn restore(&self, epoch: usize) -> Result<R, CheckpointerError> {
        let file = self.run.checkpoint_file(self.part, epoch);
        R::load(file.clone()).map_err(|e| self.failed("read", &file, cause(e)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Module;
    use burn::store::ModuleRecord;
    use burn::tensor::Device;
    use hnet_model::HNetConfig;
    use hnet_units::ImageSize;

    fn record() -> ModuleRecord {
        let config = HNetConfig::new()
            .with_filters(2)
            .with_depth(1)
            .with_image_size(ImageSize::square(8))
            .with_force_hidden([2, 2]);
        config.init(&Device::flex()).unwrap().into_record()
    }

    #[test]
    fn a_failed_write_keeps_the_last_complete_checkpoint_and_names_the_file() {
        let root = std::env::temp_dir().join(format!("hnet-checkpoints-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let run = RunDir::new(&root);
        let failure = WriteFailure::default();
        let [model, optim, scheduler] = RunCheckpointer::for_run(&run, &failure);
        for checkpointer in [&model, &optim, &scheduler] {
            Checkpointer::<ModuleRecord>::save(checkpointer, 1, record()).unwrap();
        }
        assert_eq!(run.checkpoint_epochs(), [1]);
        let first = std::fs::read(run.checkpoint_model_file(1)).unwrap();

        // A folder where epoch 2's network goes: the write fails (whoever runs the test), and
        // names the file; the optimiser's part of epoch 2 is written.
        std::fs::create_dir_all(run.checkpoint_model_file(2).join("in-the-way")).unwrap();
        let error = Checkpointer::<ModuleRecord>::save(&model, 2, record()).unwrap_err();
        let message = failure.get().unwrap();
        assert!(error.to_string().contains(&message), "{error}");
        assert!(
            message.starts_with(&format!(
                "cannot write checkpoint '{}': ",
                run.checkpoint_model_file(2).display()
            )),
            "{message}"
        );
        Checkpointer::<ModuleRecord>::save(&optim, 2, record()).unwrap();
        // Epoch 1 is the last complete checkpoint: asked to delete it, every part stays.
        for checkpointer in [&model, &optim, &scheduler] {
            Checkpointer::<ModuleRecord>::delete(checkpointer, 1).unwrap();
        }
        assert_eq!(run.checkpoint_epochs(), [1]);
        assert_eq!(std::fs::read(run.checkpoint_model_file(1)).unwrap(), first);
        let _: ModuleRecord = Checkpointer::restore(&model, 1).unwrap();
        // No temporary file is left behind.
        let names: Vec<String> = std::fs::read_dir(run.checkpoint_dir())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(
            names
                .iter()
                .all(|n| n.ends_with(".bpk") || n.ends_with(".bpk.crc32")),
            "{names:?}"
        );

        // Once epoch 3 is complete, epoch 1 goes.
        for checkpointer in [&model, &optim, &scheduler] {
            Checkpointer::<ModuleRecord>::save(checkpointer, 3, record()).unwrap();
        }
        for checkpointer in [&model, &optim, &scheduler] {
            Checkpointer::<ModuleRecord>::delete(checkpointer, 1).unwrap();
        }
        assert_eq!(run.checkpoint_epochs(), [3]);
        // The first failure is the one reported.
        assert_eq!(failure.get().unwrap(), message);
        std::fs::remove_dir_all(root).ok();
    }
}
