//! When training stops: at the end of the epoch after which the validation loss has not improved
//! for `patience` epochs (the paper's early stopping), or, with a time budget, at the end of the
//! last epoch that fits in it, so that a run on a lent machine ends cleanly with its best
//! checkpoint saved rather than being killed mid-epoch. At least one epoch always runs, and
//! exporting the best checkpoint (seconds) comes after the budget. An epoch whose mean training
//! or validation loss is not finite stops the run at once: nothing after it can recover, and
//! `hnet train` then sets that epoch's checkpoint aside (see [`non_finite_epochs`]).

use std::time::{Duration, Instant};

use burn::train::EarlyStoppingStrategy;
use burn::train::metric::store::{Aggregate, EventStoreClient, Split};

use super::checkpoints::WriteFailure;
use crate::run_dir::{EpochRow, LOSS_METRIC};

/// The epochs of `rows` whose mean loss (training or validation) is not finite.
pub fn non_finite_epochs(rows: &[EpochRow]) -> Vec<usize> {
    let mut epochs: Vec<usize> = rows
        .iter()
        .filter(|row| row.values.get(LOSS_METRIC).is_some_and(|l| !l.is_finite()))
        .map(|row| row.epoch)
        .collect();
    epochs.sort_unstable();
    epochs.dedup();
    epochs
}

/// A wall-clock budget for the epochs of this session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeBudget {
    limit: Duration,
    started: Instant,
    last_epoch_end: Instant,
    longest_epoch: Duration,
}

impl TimeBudget {
    /// A budget of `limit` from `started` (the session's start: data loading counts), for
    /// epochs from `first_epoch_starts` (so that loading is not taken for an epoch's length).
    pub fn new(limit: Duration, started: Instant, first_epoch_starts: Instant) -> Self {
        Self {
            limit,
            started,
            last_epoch_end: first_epoch_starts.max(started),
            longest_epoch: Duration::ZERO,
        }
    }

    /// Records an epoch that ended at `now`; whether one more epoch, as long as the longest so
    /// far, still ends within the budget.
    pub fn allows_another_epoch(&mut self, now: Instant) -> bool {
        let epoch = now.saturating_duration_since(self.last_epoch_end);
        self.longest_epoch = self.longest_epoch.max(epoch);
        self.last_epoch_end = now;
        now.saturating_duration_since(self.started) + self.longest_epoch <= self.limit
    }

    /// The budget.
    pub fn limit(&self) -> Duration {
        self.limit
    }
}

/// The patience rule, and the time budget when there is one.
#[derive(Clone)]
pub struct StoppingRule<P> {
    patience: P,
    budget: Option<TimeBudget>,
    write_failure: WriteFailure,
}

impl<P> StoppingRule<P> {
    /// Stops by `patience`, when the next epoch would overrun `budget`, or after an epoch in
    /// which a write to the run folder failed (`write_failure`).
    pub fn new(patience: P, budget: Option<TimeBudget>, write_failure: &WriteFailure) -> Self {
        Self {
            patience,
            budget,
            write_failure: write_failure.clone(),
        }
    }
}

impl<P: EarlyStoppingStrategy> EarlyStoppingStrategy for StoppingRule<P> {
    fn should_stop(&mut self, epoch: usize, store: &EventStoreClient) -> bool {
        if self.write_failure.get().is_some() {
            // `hnet train` says which write and where `--resume` continues.
            return true;
        }
        for split in [Split::Train, Split::Valid] {
            let loss = store.find_metric(LOSS_METRIC, epoch, Aggregate::Mean, &split);
            if loss.is_some_and(|l| !l.is_finite()) {
                eprintln!(
                    "stopping after epoch {epoch}: its mean {split} loss is not finite \
                     (the weights diverged; a smaller learning rate may help)"
                );
                return true;
            }
        }
        if self.patience.should_stop(epoch, store) {
            return true;
        }
        let Some(budget) = &mut self.budget else {
            return false;
        };
        if budget.allows_another_epoch(Instant::now()) {
            return false;
        }
        eprintln!(
            "stopping after epoch {epoch}: another epoch would not end within the time budget \
             ({})",
            crate::progress_renderer::duration_text(budget.limit())
        );
        true
    }
}

/// Parses a duration as people write it: `90s`, `12m`, `1h30m`, `2h`.
pub fn parse_duration(text: &str) -> Result<Duration, String> {
    let bad = || format!("`{text}` is not a duration such as 90s, 12m or 1h30m");
    let mut seconds = 0u64;
    let mut number = String::new();
    for c in text.trim().chars() {
        if c.is_ascii_digit() {
            number.push(c);
            continue;
        }
        let unit = match c {
            'h' => 3600,
            'm' => 60,
            's' => 1,
            _ => return Err(bad()),
        };
        let value: u64 = number.parse().map_err(|_| bad())?;
        seconds = value
            .checked_mul(unit)
            .and_then(|s| seconds.checked_add(s))
            .ok_or_else(bad)?;
        number.clear();
    }
    if !number.is_empty() || text.trim().is_empty() {
        return Err(bad());
    }
    Ok(Duration::from_secs(seconds))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epochs_whose_training_or_validation_loss_diverged_are_found_once() {
        let row = |epoch, split: &str, loss| EpochRow {
            epoch,
            split: split.into(),
            values: [(LOSS_METRIC.to_string(), loss)].into(),
        };
        let rows = [
            row(1, "train", 1.2),
            row(2, "train", f64::NAN),
            row(3, "train", f64::INFINITY),
            row(1, "valid", 1.1),
            row(2, "valid", f64::NAN),
            row(3, "valid", 0.9),
        ];
        assert_eq!(non_finite_epochs(&rows), [2, 3]);
    }

    #[test]
    fn the_budget_stops_before_an_epoch_that_would_overrun_it() {
        let t0 = Instant::now();
        let at = |s| t0 + Duration::from_secs(s);
        // 4 s of loading, then epochs of 8, 10 and 11 s.
        let mut budget = TimeBudget::new(Duration::from_secs(35), t0, at(4));
        assert!(budget.allows_another_epoch(at(12))); // 12 s + 8 s
        assert!(budget.allows_another_epoch(at(22))); // 22 s + 10 s
        assert!(!budget.allows_another_epoch(at(33))); // 33 s + 11 s > 35 s
        let mut none = TimeBudget::new(Duration::ZERO, t0, t0);
        assert!(!none.allows_another_epoch(at(1)));
    }

    #[test]
    fn durations_are_read_as_written() {
        assert_eq!(parse_duration("90s"), Ok(Duration::from_secs(90)));
        assert_eq!(parse_duration("12m"), Ok(Duration::from_secs(720)));
        assert_eq!(parse_duration("1h30m"), Ok(Duration::from_secs(5400)));
        assert_eq!(parse_duration("0s"), Ok(Duration::ZERO));
        for bad in [
            "",
            "12",
            "m",
            "1.5h",
            "ten minutes",
            "99999999999999999999h",
        ] {
            assert!(parse_duration(bad).is_err(), "{bad}");
        }
    }
}
