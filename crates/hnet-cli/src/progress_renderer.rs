//! What `hnet train` shows while it runs: a progress bar per split with the running loss, and a
//! line per finished split with its metrics (burn-train's own plain renderer prints a debug line
//! per batch).

use std::collections::{BTreeMap, HashMap};

use burn::train::LearnerSummary;
use burn::train::logger::{EvaluationProgressLogger, TrainingProgressLogger};
use burn::train::metric::{MetricDefinition, MetricId};
use burn::train::renderer::{
    EvaluationName, MetricState, MetricsRenderer, MetricsRendererEvaluation,
    MetricsRendererTraining,
};
use indicatif::ProgressBar;

/// Renders training progress on standard error.
pub struct TrainingDisplay {
    bar: ProgressBar,
    epoch: usize,
    epochs: usize,
    split: String,
    names: HashMap<MetricId, String>,
    latest: BTreeMap<String, String>,
}

impl TrainingDisplay {
    /// A display with no bar yet.
    pub fn new() -> Self {
        Self {
            bar: ProgressBar::hidden(),
            epoch: 0,
            epochs: 0,
            split: String::new(),
            names: HashMap::new(),
            latest: BTreeMap::new(),
        }
    }

    fn record(&mut self, state: &MetricState) {
        let entry = match state {
            MetricState::Generic(e) | MetricState::Numeric(e, _) => e,
        };
        if entry.serialized_entry.is_not_available() {
            return;
        }
        if let Some(name) = self.names.get(&entry.metric_id) {
            self.latest
                .insert(name.clone(), entry.serialized_entry.formatted.clone());
        }
        if let Some(loss) = self.latest.get("Loss") {
            self.bar.set_message(format!(
                "epoch {}/{} {} {loss}",
                self.epoch, self.epochs, self.split
            ));
        }
    }
}

impl MetricsRendererTraining for TrainingDisplay {
    fn update_train(&mut self, state: MetricState) {
        self.record(&state);
    }

    fn update_valid(&mut self, state: MetricState) {
        self.record(&state);
    }

    fn on_train_end(
        &mut self,
        summary: Option<LearnerSummary>,
    ) -> Result<(), Box<dyn core::error::Error>> {
        self.bar.finish_and_clear();
        if let Some(summary) = summary {
            eprintln!("{summary}");
        }
        Ok(())
    }
}

impl TrainingProgressLogger for TrainingDisplay {
    fn start(
        &mut self,
        total_epochs: usize,
        starting_epoch: usize,
        _total_items: Option<usize>,
        _label: Option<&str>,
    ) {
        self.epochs = total_epochs;
        self.epoch = starting_epoch.max(1);
    }

    fn update_epoch(&mut self, epoch: usize) {
        self.epoch = epoch + 1;
    }

    fn start_split(&mut self, split: &str, total_items: usize) {
        self.split = split.to_string();
        self.latest.clear();
        self.bar = crate::progress::bar(total_items as u64, &format!("{split} {}", self.epoch));
    }

    fn update_split(&mut self, items_processed: usize) {
        self.bar.set_position(items_processed as u64);
    }

    fn end_split(&mut self) {
        self.bar.finish_and_clear();
        let metrics: Vec<String> = self
            .latest
            .iter()
            .map(|(name, value)| format!("{name} {value}"))
            .collect();
        eprintln!(
            "epoch {}/{} {:<5} {}",
            self.epoch,
            self.epochs,
            self.split,
            metrics.join(", ")
        );
    }

    fn end(&mut self) {
        self.bar.finish_and_clear();
    }

    fn log_event_training(&mut self, event: String) {
        self.bar.println(event);
    }
}

impl EvaluationProgressLogger for TrainingDisplay {
    fn start_global_progress(&mut self, _total_tests: usize) {}

    fn start_test(&mut self, name: &str, total_items: usize) {
        self.bar = crate::progress::bar(total_items as u64, name);
    }

    fn update_test_progress(&mut self, items_processed: usize) {
        self.bar.set_position(items_processed as u64);
    }

    fn end_test(&mut self) {
        self.bar.finish_and_clear();
    }

    fn end_global_progress(&mut self) {}

    fn log_event_evaluation(&mut self, event: String) {
        self.bar.println(event);
    }
}

impl MetricsRendererEvaluation for TrainingDisplay {
    fn update_test(&mut self, _name: EvaluationName, state: MetricState) {
        self.record(&state);
    }
}

impl MetricsRenderer for TrainingDisplay {
    fn manual_close(&mut self) {
        self.bar.finish_and_clear();
    }

    fn register_metric(&mut self, definition: MetricDefinition) {
        self.names
            .insert(definition.metric_id.clone(), definition.name.to_string());
    }
}
