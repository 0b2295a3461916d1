//! What `hnet train` logs each epoch besides the total loss: the loss terms, the paper's
//! segmentation metrics and the force error, over the heads the network has. Their names are the
//! ones in the run folder's logs (`crate::run_dir`) and `hnet report`'s figures.

use std::sync::Arc;

use burn::tensor::TensorReadError;
use burn::train::metric::state::{FormatOptions, NumericMetricState};
use burn::train::metric::{
    Metric, MetricAttributes, MetricMetadata, MetricName, Numeric, NumericAttributes, NumericEntry,
    SerializedEntry,
};

/// Host values of one step, computed once for all metrics with [`hnet_model::metrics`].
#[derive(Debug, Clone, Copy)]
pub struct StepSummary {
    /// Pairs in the batch.
    pub batch_size: usize,
    /// View A's mean BCE.
    pub bce_a: f64,
    /// View B's mean BCE.
    pub bce_b: f64,
    /// Force MSE, N².
    pub mse: f64,
    /// Mean IoU over both views and both classes (networks that segment).
    pub miou: Option<f64>,
    /// Mean Dice over both views and both classes.
    pub mdice: Option<f64>,
    /// Force MAE over the three axes and the pairs with a force label, N (networks that
    /// estimate the force; `None` also when no pair in the batch has a label).
    pub force_mae: Option<f64>,
}

/// A metric's input: the step's host values.
pub struct StepInput(pub Result<StepSummary, String>);

/// The quantities logged besides the total loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// View A's BCE.
    BceA,
    /// View B's BCE.
    BceB,
    /// Force MSE (N²).
    Mse,
    /// Mean IoU over both views and both classes.
    MIoU,
    /// Mean Dice over both views and both classes.
    MDice,
    /// Force MAE over the three axes (N).
    ForceMae,
}

impl Quantity {
    /// All of them.
    pub const ALL: [Quantity; 6] = [
        Quantity::BceA,
        Quantity::BceB,
        Quantity::Mse,
        Quantity::MIoU,
        Quantity::MDice,
        Quantity::ForceMae,
    ];

    /// Whether a network with these heads (`(segments, estimates force)`, as
    /// [`hnet_model::architectures::ModelSpec::heads`] gives them) produces this quantity.
    pub fn applies_to(self, (segments, forces): (bool, bool)) -> bool {
        match self {
            Quantity::BceA | Quantity::BceB | Quantity::MIoU | Quantity::MDice => segments,
            Quantity::Mse | Quantity::ForceMae => forces,
        }
    }

    /// The metric's name in logs.
    pub fn name(self) -> &'static str {
        match self {
            Quantity::BceA => "BCE A",
            Quantity::BceB => "BCE B",
            Quantity::Mse => "Force MSE",
            Quantity::MIoU => "mIoU",
            Quantity::MDice => "mDice",
            Quantity::ForceMae => "Force MAE",
        }
    }

    fn of(self, s: &StepSummary) -> Option<f64> {
        match self {
            Quantity::BceA => Some(s.bce_a),
            Quantity::BceB => Some(s.bce_b),
            Quantity::Mse => Some(s.mse),
            Quantity::MIoU => s.miou,
            Quantity::MDice => s.mdice,
            Quantity::ForceMae => s.force_mae,
        }
    }
}

/// A numeric metric averaged over an epoch, weighted by batch size.
#[derive(Clone)]
pub struct StepMetric {
    quantity: Quantity,
    name: MetricName,
    state: NumericMetricState,
}

impl StepMetric {
    /// The metric of `quantity`.
    pub fn new(quantity: Quantity) -> Self {
        Self {
            quantity,
            name: Arc::new(quantity.name().to_string()),
            state: NumericMetricState::default(),
        }
    }
}

impl Metric for StepMetric {
    type Input = StepInput;

    fn update(
        &mut self,
        input: &StepInput,
        _metadata: &MetricMetadata,
    ) -> Result<SerializedEntry, TensorReadError> {
        let summary = match &input.0 {
            Ok(s) => s,
            Err(_) => return Ok(SerializedEntry::not_available(None)),
        };
        match self.quantity.of(summary) {
            Some(value) => {
                self.state.update(value, summary.batch_size);
                Ok(self
                    .state
                    .compute_update(FormatOptions::new(self.name()).precision(4)))
            }
            None => Ok(SerializedEntry::not_available(None)),
        }
    }

    fn compute(&mut self) -> Result<SerializedEntry, TensorReadError> {
        Ok(self
            .state
            .compute_final(FormatOptions::new(self.name()).precision(4)))
    }

    fn clear(&mut self) {
        self.state.reset()
    }

    fn name(&self) -> MetricName {
        self.name.clone()
    }

    fn attributes(&self) -> MetricAttributes {
        NumericAttributes {
            unit: None,
            higher_is_better: matches!(self.quantity, Quantity::MIoU | Quantity::MDice),
        }
        .into()
    }
}

impl Numeric for StepMetric {
    fn value(&self) -> Option<NumericEntry> {
        Some(self.state.current_value())
    }

    fn running_value(&self) -> Option<NumericEntry> {
        Some(self.state.running_value())
    }

    fn final_value(&self) -> NumericEntry {
        self.state.final_value()
    }
}
