//! What `hnet train` shows while it runs. On a terminal: a bar per split that redraws in place
//! with pairs done of the total, pairs per second, the time left and the running loss. Otherwise
//! (a log file, CI): a plain line every [`PLAIN_EVERY`] with the same figures. Either way, a line
//! per finished split with its metrics, and a summary at the end.
//!
//! burn-train reports every batch as an `Iteration` event; those are counted, not printed.

use std::collections::{BTreeMap, HashMap};
use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use burn::train::LearnerSummary;
use burn::train::logger::{EvaluationProgressLogger, TrainingProgressLogger};
use burn::train::metric::{MetricDefinition, MetricId, NumericEntry};
use burn::train::renderer::{
    EvaluationName, MetricState, MetricsRenderer, MetricsRendererEvaluation,
    MetricsRendererTraining,
};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::run_dir::LOSS_METRIC;

/// How often a plain progress line is written when the output is not a terminal.
pub const PLAIN_EVERY: Duration = Duration::from_secs(30);

/// burn-train's per-batch event: counted by the bar, never printed.
const BATCH_EVENT: &str = "Iteration";

/// Where the progress goes.
enum Output {
    /// A terminal: a bar per split on the draw target `target` makes.
    Terminal {
        target: Box<dyn Fn() -> ProgressDrawTarget + Send + Sync>,
        bar: ProgressBar,
    },
    /// Anything else: plain lines, a progress line at most every `every`.
    Plain {
        write: Box<dyn Write + Send + Sync>,
        every: Duration,
        last: Option<Instant>,
    },
}

/// Renders training progress (see the module's documentation).
pub struct TrainingDisplay {
    output: Output,
    epoch: usize,
    epochs: usize,
    split: String,
    /// Pairs in the current split, and done so far.
    total: usize,
    done: usize,
    split_started: Instant,
    run_started: Instant,
    /// Training pairs seen over the whole run, and the time spent on them.
    trained_pairs: usize,
    training_time: Duration,
    names: HashMap<MetricId, String>,
    /// Each numeric metric's mean over the split so far: its sum and its count (pairs).
    means: BTreeMap<String, (f64, f64)>,
}

impl TrainingDisplay {
    /// A bar on standard error when it is a terminal, plain lines there otherwise.
    pub fn new() -> Self {
        if std::io::stderr().is_terminal() {
            Self::terminal(Box::new(ProgressDrawTarget::stderr))
        } else {
            Self::plain(Box::new(std::io::stderr()), PLAIN_EVERY)
        }
    }

    /// Bars drawn on the targets `target` makes (one per split).
    pub fn terminal(target: Box<dyn Fn() -> ProgressDrawTarget + Send + Sync>) -> Self {
        Self::with(Output::Terminal {
            target,
            bar: ProgressBar::hidden(),
        })
    }

    /// Plain lines on `write`, a progress line at most every `every`.
    pub fn plain(write: Box<dyn Write + Send + Sync>, every: Duration) -> Self {
        Self::with(Output::Plain {
            write,
            every,
            last: None,
        })
    }

    fn with(output: Output) -> Self {
        Self {
            output,
            epoch: 0,
            epochs: 0,
            split: String::new(),
            total: 0,
            done: 0,
            split_started: Instant::now(),
            run_started: Instant::now(),
            trained_pairs: 0,
            training_time: Duration::ZERO,
            names: HashMap::new(),
            means: BTreeMap::new(),
        }
    }

    /// Writes a whole line (above the bar on a terminal).
    fn line(&mut self, text: &str) {
        match &mut self.output {
            Output::Terminal { bar, .. } => {
                if bar.is_hidden() {
                    eprintln!("{text}");
                } else {
                    bar.println(text);
                }
            }
            Output::Plain { write, .. } => {
                let _ = writeln!(write, "{text}");
                let _ = write.flush();
            }
        }
    }

    /// A metric's mean over the split so far.
    fn mean(&self, name: &str) -> Option<f64> {
        self.means
            .get(name)
            .and_then(|(sum, count)| (*count > 0.0).then(|| sum / count))
    }

    fn loss(&self) -> Option<String> {
        self.mean(LOSS_METRIC).map(|l| format!("{l:.4}"))
    }

    /// `epoch 3/18 train`.
    fn label(&self) -> String {
        format!("epoch {}/{} {:<5}", self.epoch, self.epochs, self.split)
    }

    /// The progress line of plain output.
    fn progress_line(&self) -> String {
        let elapsed = self.split_started.elapsed().as_secs_f64();
        let rate = if elapsed > 0.0 {
            self.done as f64 / elapsed
        } else {
            0.0
        };
        let eta = if rate > 0.0 {
            duration_text(Duration::from_secs_f64(
                (self.total.saturating_sub(self.done)) as f64 / rate,
            ))
        } else {
            "?".into()
        };
        let percent = 100.0 * self.done as f64 / self.total.max(1) as f64;
        let mut text = format!(
            "{} {}/{} pairs ({percent:.0}%), {rate:.1} pairs/s, ETA {eta}",
            self.label(),
            self.done,
            self.total
        );
        if let Some(loss) = self.loss() {
            text.push_str(&format!(", loss {loss}"));
        }
        text
    }

    /// Adds a batch's value to its metric's running mean (weighted by the batch's pairs); an
    /// epoch's final value replaces the mean.
    fn record(&mut self, state: &MetricState) {
        let MetricState::Numeric(entry, Some(value)) = state else {
            return;
        };
        let Some(name) = self.names.get(&entry.metric_id) else {
            return;
        };
        let mean = self.means.entry(name.clone()).or_insert((0.0, 0.0));
        match value {
            NumericEntry::Value(v) => {
                mean.0 += v;
                mean.1 += 1.0;
            }
            NumericEntry::Aggregated {
                aggregated_value,
                count,
            } => {
                mean.0 += aggregated_value * *count as f64;
                mean.1 += *count as f64;
            }
            NumericEntry::Final(v) => *mean = (*v, 1.0),
        }
        if let (Output::Terminal { bar, .. }, Some(loss)) = (&self.output, self.loss()) {
            bar.set_message(format!("loss {loss}"));
        }
    }

    fn start_bar(&mut self, prefix: String, total: usize) {
        self.split_started = Instant::now();
        self.total = total;
        self.done = 0;
        if let Output::Terminal { target, bar } = &mut self.output {
            *bar = ProgressBar::with_draw_target(Some(total as u64), target());
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix} [{bar:30}] {pos}/{len} pairs, {per_sec}, ETA {eta} {msg}",
                )
                .expect("a valid template")
                .progress_chars("=> "),
            );
            bar.set_prefix(prefix);
        }
    }

    fn advance(&mut self, done: usize) {
        self.done = done;
        match &mut self.output {
            Output::Terminal { bar, .. } => bar.set_position(done as u64),
            Output::Plain { every, last, .. } => {
                let due = last.is_none_or(|t| t.elapsed() >= *every);
                if due && done < self.total {
                    *last = Some(Instant::now());
                    let line = self.progress_line();
                    self.line(&line);
                }
            }
        }
    }

    fn finish_bar(&mut self) {
        if let Output::Terminal { bar, .. } = &self.output {
            bar.finish_and_clear();
        }
    }
}

impl Default for TrainingDisplay {
    fn default() -> Self {
        Self::new()
    }
}

/// `1h02m`, `4m05s` or `12s`.
pub fn duration_text(d: Duration) -> String {
    let s = d.as_secs();
    if s >= 3600 {
        format!("{}h{:02}m", s / 3600, (s % 3600) / 60)
    } else if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
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
        self.finish_bar();
        if let Some(summary) = summary {
            self.line(&summary.to_string());
        }
        let rate = self.trained_pairs as f64 / self.training_time.as_secs_f64().max(1e-9);
        let text = format!(
            "training ended after {} ({} training pairs, {rate:.1} pairs/s while training)",
            duration_text(self.run_started.elapsed()),
            self.trained_pairs
        );
        self.line(&text);
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
        self.run_started = Instant::now();
    }

    fn update_epoch(&mut self, epoch: usize) {
        self.epoch = epoch + 1;
    }

    fn start_split(&mut self, split: &str, total_items: usize) {
        self.split = split.to_string();
        self.means.clear();
        let prefix = self.label();
        self.start_bar(prefix, total_items);
        if let Output::Plain { last, .. } = &mut self.output {
            // The first line of a split comes after `every`, not at once.
            *last = Some(Instant::now());
        }
    }

    fn update_split(&mut self, items_processed: usize) {
        self.advance(items_processed);
    }

    fn end_split(&mut self) {
        let elapsed = self.split_started.elapsed();
        if self.split == "train" {
            self.trained_pairs += self.done;
            self.training_time += elapsed;
        }
        let metrics: Vec<String> = self
            .means
            .keys()
            .filter_map(|name| self.mean(name).map(|m| format!("{name} {m:.4}")))
            .collect();
        let text = format!(
            "{} {} pairs in {}, {}",
            self.label(),
            self.done,
            duration_text(elapsed),
            metrics.join(", ")
        );
        self.line(&text);
        self.finish_bar();
    }

    fn end(&mut self) {
        self.finish_bar();
    }

    fn log_event_training(&mut self, event: String) {
        if event != BATCH_EVENT {
            self.line(&event);
        }
    }
}

impl EvaluationProgressLogger for TrainingDisplay {
    fn start_global_progress(&mut self, _total_tests: usize) {}

    fn start_test(&mut self, name: &str, total_items: usize) {
        self.split = name.to_string();
        self.start_bar(name.to_string(), total_items);
    }

    fn update_test_progress(&mut self, items_processed: usize) {
        self.advance(items_processed);
    }

    fn end_test(&mut self) {
        self.finish_bar();
    }

    fn end_global_progress(&mut self) {}

    fn log_event_evaluation(&mut self, event: String) {
        if event != BATCH_EVENT {
            self.line(&event);
        }
    }
}

impl MetricsRendererEvaluation for TrainingDisplay {
    fn update_test(&mut self, _name: EvaluationName, state: MetricState) {
        self.record(&state);
    }
}

impl MetricsRenderer for TrainingDisplay {
    fn manual_close(&mut self) {
        self.finish_bar();
    }

    fn register_metric(&mut self, definition: MetricDefinition) {
        self.names
            .insert(definition.metric_id.clone(), definition.name.to_string());
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use super::*;

    /// Everything written, shared with the display under test.
    #[derive(Debug, Clone, Default)]
    struct Recorder(Arc<Mutex<String>>);

    impl Write for Recorder {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0
                .lock()
                .unwrap()
                .push_str(&String::from_utf8_lossy(buf));
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl indicatif::TermLike for Recorder {
        fn width(&self) -> u16 {
            160
        }
        fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn write_line(&self, s: &str) -> std::io::Result<()> {
            self.0.lock().unwrap().push_str(&format!("{s}\n"));
            Ok(())
        }
        fn write_str(&self, s: &str) -> std::io::Result<()> {
            self.0.lock().unwrap().push_str(s);
            Ok(())
        }
        fn clear_line(&self) -> std::io::Result<()> {
            self.0.lock().unwrap().push_str("<clear>");
            Ok(())
        }
        fn flush(&self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// One epoch of 4 batches of 8 training pairs, then 2 of validation.
    fn run_epoch(display: &mut TrainingDisplay) {
        display.start(18, 1, None, None);
        display.start_split("train", 32);
        for batch in 1..=4 {
            std::thread::sleep(Duration::from_millis(5));
            display.update_split(batch * 8);
            display.log_event_training(BATCH_EVENT.to_string());
        }
        display.end_split();
        display.start_split("valid", 16);
        display.update_split(8);
        display.update_split(16);
        display.end_split();
        display.update_epoch(0);
        display.end();
    }

    #[test]
    fn plain_output_has_counts_rates_and_no_batch_events() {
        let recorder = Recorder::default();
        let mut display = TrainingDisplay::plain(Box::new(recorder.clone()), Duration::ZERO);
        run_epoch(&mut display);
        let text = recorder.0.lock().unwrap().clone();
        assert!(!text.contains(BATCH_EVENT), "{text}");
        let lines: Vec<&str> = text.lines().collect();
        // Three progress lines (the last batch ends the split instead), then the split's line.
        for (line, start) in [
            (0, "epoch 1/18 train 8/32 pairs (25%), "),
            (2, "epoch 1/18 train 24/32 pairs (75%)"),
            (3, "epoch 1/18 train 32 pairs in "),
            (4, "epoch 1/18 valid 8/16 pairs (50%)"),
            (5, "epoch 1/18 valid 16 pairs in "),
        ] {
            assert!(lines[line].starts_with(start), "line {line}: {text}");
        }
        assert!(lines[0].contains(" pairs/s, ETA "), "{text}");
        assert_eq!(lines.len(), 6, "{text}");

        // At the default interval, a short epoch writes only the split lines.
        let quiet = Recorder::default();
        let mut display = TrainingDisplay::plain(Box::new(quiet.clone()), PLAIN_EVERY);
        run_epoch(&mut display);
        assert_eq!(quiet.0.lock().unwrap().lines().count(), 2);
    }

    #[test]
    fn a_terminal_gets_a_bar_that_redraws_in_place() {
        let recorder = Recorder::default();
        let target = recorder.clone();
        let mut display = TrainingDisplay::terminal(Box::new(move || {
            ProgressDrawTarget::term_like(Box::new(target.clone()))
        }));
        run_epoch(&mut display);
        let text = recorder.0.lock().unwrap().clone();
        assert!(!text.contains(BATCH_EVENT), "{text}");
        assert!(text.contains("epoch 1/18 train ["), "{text}");
        assert!(text.contains("/32 pairs, "), "{text}");
        assert!(text.contains("ETA "), "{text}");
        // Redrawn in place: the bar's line is cleared, not followed by a new line per batch.
        assert!(text.contains("<clear>"), "{text}");
        assert!(text.contains("epoch 1/18 train 32 pairs in "), "{text}");
        assert!(text.contains("epoch 1/18 valid 16 pairs in "), "{text}");
    }

    #[test]
    fn durations_read_as_people_write_them() {
        assert_eq!(duration_text(Duration::from_secs(12)), "12s");
        assert_eq!(duration_text(Duration::from_secs(245)), "4m05s");
        assert_eq!(duration_text(Duration::from_secs(3720)), "1h02m");
    }
}
