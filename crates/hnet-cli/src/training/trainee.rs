//! The network with its loss as burn-train trains it: the one training step
//! ([`hnet_model::training::step_loss`], shared with the page's fine-tuning), and the step's
//! host values that every logged metric reads.

use std::sync::{Arc, OnceLock};

use burn::module::Module;
use burn::tensor::{ExecutionError, Tensor};
use burn::train::metric::{Adaptor, ItemLazy, LossInput};
use burn::train::{InferenceStep, Interrupter, TrainOutput, TrainStep};
use hnet_model::HNetLossConfig;
use hnet_model::architectures::{ModelSpec, StereoInput, StereoModel};
use hnet_model::inference::host_values;
use hnet_model::metrics::{ForceAccumulator, SegmentationAccumulator};
use hnet_model::training::{StepLoss, step_loss};
use hnet_units::TipForce;

use super::metrics::{StepInput, StepSummary};
use hnet_model::training::TrainingBatch;

/// The network with its loss, as burn-train sees it.
#[derive(Module, Debug)]
pub struct StereoTrainee {
    /// The network.
    pub net: StereoModel,
    #[module(skip)]
    loss: HNetLossConfig,
    #[module(skip)]
    input: StereoInput,
    #[module(skip)]
    heads: (bool, bool),
    #[module(skip)]
    divergence: DivergenceStop,
}

/// Stops the run at the first training step whose loss is not finite, rather than at the end
/// of its epoch: every step after it would train on NaN weights.
#[derive(Clone, Default)]
struct DivergenceStop(Option<Interrupter>);

impl core::fmt::Debug for DivergenceStop {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(if self.0.is_some() {
            "DivergenceStop(on)"
        } else {
            "DivergenceStop(off)"
        })
    }
}

/// Why a run stopped mid-epoch (`hnet train` prints it).
const DIVERGED_STEP: &str =
    "a training step's loss is not finite (the weights diverged; a smaller learning rate may help)";

impl DivergenceStop {
    /// Stops the run when `loss` is not finite (a loss that cannot be read back is left to the
    /// epoch's end).
    fn check(&self, loss: &Tensor<1>) {
        let Some(interrupter) = &self.0 else {
            return;
        };
        let finite = loss
            .clone()
            .try_into_scalar::<f64>()
            .map_or(true, f64::is_finite);
        if !finite && !interrupter.should_stop() {
            interrupter.stop(Some(DIVERGED_STEP));
        }
    }
}

impl StereoTrainee {
    /// Wraps `net` built from `spec` with the loss weights.
    pub fn new(net: StereoModel, spec: &ModelSpec, loss: HNetLossConfig) -> Self {
        Self {
            net,
            loss,
            input: spec.input(),
            heads: spec.heads(),
            divergence: DivergenceStop::default(),
        }
    }

    /// The same, stopping `interrupter`'s run at the first training step whose loss is not
    /// finite.
    pub fn stopping_on_divergence(mut self, interrupter: Interrupter) -> Self {
        self.divergence = DivergenceStop(Some(interrupter));
        self
    }

    fn run(&self, batch: TrainingBatch) -> StereoStepOutput {
        let StepLoss { outputs, terms } =
            step_loss(&self.net, self.input, &self.loss.init(), &batch);
        StereoStepOutput {
            total: terms.total,
            bce_a: terms.bce_a,
            bce_b: terms.bce_b,
            mse: terms.mse,
            predicted_masks: outputs
                .mask_logits
                .map(|logits| logits.map(|l| burn::tensor::activation::sigmoid(l.detach()))),
            target_masks: [batch.mask_a, batch.mask_b],
            predicted_force: outputs.force.map(|f| f.detach()),
            target_force: batch.force,
            force_known: batch.force_known,
            summary: Arc::new(OnceLock::new()),
        }
    }
}

/// One step's results: the loss terms (kept on the graph for the backward pass) and what the
/// metrics need.
#[derive(Debug, Clone)]
pub struct StereoStepOutput {
    total: Tensor<1>,
    bce_a: Tensor<1>,
    bce_b: Tensor<1>,
    mse: Tensor<1>,
    predicted_masks: Option<[Tensor<4>; 2]>,
    target_masks: [Tensor<4>; 2],
    predicted_force: Option<Tensor<2>>,
    target_force: Tensor<2>,
    force_known: Tensor<2>,
    summary: Arc<OnceLock<Result<StepSummary, String>>>,
}

/// A tensor's values on the host.
fn host<const D: usize>(t: &Tensor<D>) -> Result<Vec<f32>, String> {
    host_values(t.clone()).map_err(|e| e.to_string())
}

fn scalar(t: &Tensor<1>) -> Result<f64, String> {
    t.clone()
        .try_into_scalar::<f64>()
        .map_err(|e| format!("{e:?}"))
}

impl StereoStepOutput {
    fn summary(&self) -> Result<StepSummary, String> {
        self.summary
            .get_or_init(|| {
                let batch_size = self.target_force.dims()[0];
                let (miou, mdice) = match &self.predicted_masks {
                    Some(predicted) => {
                        let mut acc = SegmentationAccumulator::new();
                        for (p, t) in predicted.iter().zip(&self.target_masks) {
                            acc.push(&host(p)?, &host(t)?).map_err(|e| e.to_string())?;
                        }
                        let m = acc.finish().ok_or("empty batch")?;
                        (Some(m.miou), Some(m.mdice))
                    }
                    None => (None, None),
                };
                let force_mae = match &self.predicted_force {
                    Some(p) => {
                        let (p, t) = (host(p)?, host(&self.target_force)?);
                        let known = host(&self.force_known)?;
                        let mut acc = ForceAccumulator::new();
                        let labelled = p.chunks_exact(3).zip(t.chunks_exact(3)).zip(known);
                        for ((p, t), _) in labelled.filter(|(_, k)| *k > 0.5) {
                            acc.push(
                                TipForce::new(p[0], p[1], p[2]),
                                TipForce::new(t[0], t[1], t[2]),
                            );
                        }
                        acc.finish().map(|m| m.overall.mae)
                    }
                    None => None,
                };
                Ok(StepSummary {
                    batch_size,
                    bce_a: scalar(&self.bce_a)?,
                    bce_b: scalar(&self.bce_b)?,
                    mse: scalar(&self.mse)?,
                    miou,
                    mdice,
                    force_mae,
                })
            })
            .clone()
    }
}

impl ItemLazy for StereoStepOutput {
    fn sync(self) -> Result<Self, ExecutionError> {
        Ok(self)
    }
}

impl Adaptor<LossInput> for StereoStepOutput {
    fn adapt(&self) -> LossInput {
        LossInput::new(self.total.clone())
    }
}

impl Adaptor<StepInput> for StereoStepOutput {
    fn adapt(&self) -> StepInput {
        StepInput(self.summary())
    }
}

impl TrainStep for StereoTrainee {
    type Input = TrainingBatch;
    type Output = StereoStepOutput;

    fn step(&self, batch: TrainingBatch) -> TrainOutput<StereoStepOutput> {
        let output = self.run(batch);
        self.divergence.check(&output.total);
        let grads = output.total.backward();
        TrainOutput::new(self, grads, output)
    }
}

impl InferenceStep for StereoTrainee {
    type Input = TrainingBatch;
    type Output = StereoStepOutput;

    fn step(&self, batch: TrainingBatch) -> StereoStepOutput {
        self.run(batch)
    }
}
