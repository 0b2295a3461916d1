//! `hnet train`: H-Net (or a baseline) on a dataset with Burn's `burn-train` learner.
//!
//! RMSprop at the paper's learning rate, per-epoch checkpoints, early stopping on the validation
//! loss, the best checkpoint exported as the run's `model.bpk`. A run killed at any moment resumes
//! from its last complete checkpoint with `--resume`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use anyhow::{Context, bail};
use burn::data::dataloader::DataLoaderBuilder;
use burn::module::Module;
use burn::module::ParamGroup;
use burn::optim::RmsPropConfig;
use burn::optim::lr_scheduler::module_lr_scheduler::ModuleLrScheduler;
use burn::tensor::ExecutionError;
use burn::tensor::{Device, Tensor, TensorReadError};
use burn::train::metric::state::{FormatOptions, NumericMetricState};
use burn::train::metric::store::{Aggregate, Direction, Split as MetricSplit};
use burn::train::metric::{
    Adaptor, ItemLazy, LossInput, LossMetric, Metric, MetricAttributes, MetricMetadata, MetricName,
    Numeric, NumericAttributes, NumericEntry, SerializedEntry,
};
use burn::train::{
    InferenceStep, Learner, MetricEarlyStoppingStrategy, StoppingCondition, SupervisedTraining,
    TrainOutput, TrainStep,
};
use hnet_model::architectures::{ModelSpec, StereoInput, StereoModel};
use hnet_model::loss::binary_cross_entropy_with_logits;
use hnet_model::metrics::{ForceAccumulator, SegmentationAccumulator};
use hnet_model::{HNet, HNetLossConfig};
use hnet_twin::dataset::{Dataset, Split};
use serde::{Deserialize, Serialize};

use crate::backend::BackendChoice;
use crate::data::{StereoBatch, StereoBatcher, StereoSplit};

/// Everything that defines a training run (`config.json` in the run folder).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingConfig {
    /// A short name for the settings (`paper`, `cpu`, ...).
    pub name: String,
    /// The network and its settings.
    pub model: ModelSpec,
    /// Input size `[height, width]`; images are resized to it.
    pub image_size: [usize; 2],
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
    /// Threads decoding batches.
    pub num_workers: usize,
}

impl TrainingConfig {
    fn check(&self) -> anyhow::Result<()> {
        let multiple = self.model.size_multiple();
        if self.image_size.iter().any(|s| *s == 0 || s % multiple != 0) {
            bail!(
                "image size {}x{} must be a positive multiple of {multiple} for {}",
                self.image_size[0],
                self.image_size[1],
                self.model
            );
        }
        if let ModelSpec::Hnet(c) = &self.model
            && c.image_size != self.image_size
        {
            bail!(
                "the H-Net config's image_size {:?} differs from the training image_size {:?}",
                c.image_size,
                self.image_size
            );
        }
        if self.batch_size == 0 || self.epochs == 0 {
            bail!("batch_size and epochs must be at least 1");
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

/// The network with its loss, as burn-train sees it.
#[derive(Module, Debug)]
pub struct StereoTrainee {
    /// The network.
    pub net: StereoModel,
    #[module(skip)]
    loss: HNetLossConfig,
    #[module(skip)]
    input: InputKind,
    #[module(skip)]
    heads: (bool, bool),
}

/// [`StereoInput`] as a plain value the module derive can skip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum InputKind {
    Images,
    Masks,
}

impl StereoTrainee {
    /// Wraps `net` built from `spec` with the loss weights.
    pub fn new(net: StereoModel, spec: &ModelSpec, loss: HNetLossConfig) -> Self {
        Self {
            net,
            loss,
            input: match spec.input() {
                StereoInput::Images => InputKind::Images,
                StereoInput::Masks => InputKind::Masks,
            },
            heads: spec.heads(),
        }
    }

    fn run(&self, batch: StereoBatch) -> StereoStepOutput {
        let masks = [batch.mask_a.clone(), batch.mask_b.clone()];
        let views = match self.input {
            InputKind::Images => [batch.view_a, batch.view_b],
            InputKind::Masks => masks.clone(),
        };
        let out = self.net.forward(views, masks.clone());
        let device = batch.force.device();
        let zero = || Tensor::<1>::zeros([1], &device);
        let (bce_a, bce_b, predicted_masks) = match out.mask_logits {
            Some([la, lb]) => (
                binary_cross_entropy_with_logits(la.clone(), masks[0].clone()),
                binary_cross_entropy_with_logits(lb.clone(), masks[1].clone()),
                Some([
                    burn::tensor::activation::sigmoid(la.detach()),
                    burn::tensor::activation::sigmoid(lb.detach()),
                ]),
            ),
            None => (zero(), zero(), None),
        };
        let mse = match &out.force {
            Some(f) => (f.clone() - batch.force.clone()).square().mean(),
            None => zero(),
        };
        let total = bce_a.clone().mul_scalar(self.loss.beta_a)
            + bce_b.clone().mul_scalar(self.loss.beta_b)
            + mse.clone().mul_scalar(self.loss.beta_force);
        StereoStepOutput {
            total,
            bce_a,
            bce_b,
            mse,
            predicted_masks,
            target_masks: masks,
            predicted_force: out.force.map(|f| f.detach()),
            target_force: batch.force,
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
    summary: Arc<OnceLock<Result<StepSummary, String>>>,
}

/// Host values of one step, computed once for all metrics with [`hnet_model::metrics`].
#[derive(Debug, Clone, Copy)]
pub struct StepSummary {
    batch_size: usize,
    bce_a: f64,
    bce_b: f64,
    mse: f64,
    miou: Option<f64>,
    mdice: Option<f64>,
    force_mae: Option<f64>,
}

fn host(t: &Tensor<4>) -> Result<Vec<f32>, String> {
    t.to_data()
        .try_into_vec::<f32>()
        .map_err(|e| format!("{e:?}"))
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
                        let to_vec = |t: &Tensor<2>| {
                            t.to_data()
                                .try_into_vec::<f32>()
                                .map_err(|e| format!("{e:?}"))
                        };
                        let (p, t) = (to_vec(p)?, to_vec(&self.target_force)?);
                        let mut acc = ForceAccumulator::new();
                        for (p, t) in p.chunks_exact(3).zip(t.chunks_exact(3)) {
                            acc.push([p[0], p[1], p[2]], [t[0], t[1], t[2]]);
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
    type Input = StereoBatch;
    type Output = StereoStepOutput;

    fn step(&self, batch: StereoBatch) -> TrainOutput<StereoStepOutput> {
        let output = self.run(batch);
        let grads = output.total.backward();
        TrainOutput::new(self, grads, output)
    }
}

impl InferenceStep for StereoTrainee {
    type Input = StereoBatch;
    type Output = StereoStepOutput;

    fn step(&self, batch: StereoBatch) -> StereoStepOutput {
        self.run(batch)
    }
}

/// A metric's input: the step's host values.
pub struct StepInput(Result<StepSummary, String>);

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
    /// [`ModelSpec::heads`] gives them) produces this quantity.
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

/// What `hnet train` was asked to do.
#[derive(Debug, Clone)]
pub struct TrainRequest {
    /// The dataset folder.
    pub data: PathBuf,
    /// The run folder.
    pub out: PathBuf,
    /// The settings.
    pub config: TrainingConfig,
    /// Where to compute.
    pub backend: BackendChoice,
    /// Continue the run in `out` from its last checkpoint.
    pub resume: bool,
    /// The command line, for the model card.
    pub command: String,
}

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

/// The epochs with a complete checkpoint (model, optimiser and scheduler) in `run`.
pub fn checkpoint_epochs(run: &Path) -> Vec<usize> {
    let dir = run.join("checkpoint");
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
                    ["optim", "scheduler"]
                        .iter()
                        .all(|k| dir.join(format!("{k}-{epoch}.bpk")).is_file())
                })
                .collect()
        })
        .unwrap_or_default();
    epochs.sort_unstable();
    epochs
}

/// Runs (or resumes) a training and writes the best model to `out/model.bpk`.
pub fn train(request: &TrainRequest) -> anyhow::Result<()> {
    let out = &request.out;
    let config_path = out.join("config.json");
    let info_path = out.join("run.json");
    let config = &request.config;
    config.check()?;
    let resume_from = if request.resume {
        let saved: TrainingConfig = serde_json::from_slice(
            &std::fs::read(&config_path)
                .with_context(|| format!("--resume: no run to resume in '{}'", out.display()))?,
        )
        .with_context(|| format!("'{}' is not a training config", config_path.display()))?;
        if &saved != config {
            bail!(
                "--resume: the run in '{}' was started with other settings",
                out.display()
            );
        }
        checkpoint_epochs(out).last().copied()
    } else {
        if out.exists() && std::fs::read_dir(out)?.next().is_some() {
            bail!(
                "run folder '{}' is not empty: choose another --out, or pass --resume to continue it",
                out.display()
            );
        }
        std::fs::create_dir_all(out)
            .with_context(|| format!("cannot create run folder '{}'", out.display()))?;
        std::fs::write(&config_path, serde_json::to_vec_pretty(config)?)?;
        None
    };
    std::fs::write(
        &info_path,
        serde_json::to_vec_pretty(&RunInfo {
            // Absolute, so that `hnet eval` and `hnet report` find it from any folder.
            data: std::fs::canonicalize(&request.data).unwrap_or_else(|_| request.data.clone()),
            backend: request.backend.name().into(),
            command: request.command.clone(),
        })?,
    )?;

    let dataset = Dataset::open(&request.data)?;
    let started = Instant::now();
    let train_split = StereoSplit::load(
        &dataset,
        Split::Train,
        config.image_size,
        config.max_train_samples,
    )?;
    let valid_split = StereoSplit::load(
        &dataset,
        Split::Val,
        config.image_size,
        config.max_valid_samples,
    )?;
    if train_split.items.is_empty() || valid_split.items.is_empty() {
        bail!(
            "{} needs pairs in both the train and val splits",
            request.data.display()
        );
    }
    eprintln!(
        "loaded {} training and {} validation pairs at {}x{} in {:.1} s",
        train_split.items.len(),
        valid_split.items.len(),
        config.image_size[1],
        config.image_size[0],
        started.elapsed().as_secs_f64()
    );

    let device: Device = request.backend.device()?;
    device.seed(config.seed);
    let batcher = StereoBatcher {
        size: config.image_size,
    };
    let loader_train = DataLoaderBuilder::new(batcher.clone())
        .batch_size(config.batch_size)
        .shuffle(config.seed)
        .num_workers(config.num_workers)
        .set_device(device.clone().autodiff())
        .build(train_split);
    let loader_valid = DataLoaderBuilder::new(batcher)
        .batch_size(config.batch_size)
        .num_workers(config.num_workers)
        .set_device(device.clone())
        .build(valid_split);

    let net = config
        .model
        .init(&device.clone().autodiff())
        .map_err(anyhow::Error::msg)?;
    let trainee = StereoTrainee::new(net, &config.model, config.loss.clone());
    let optimizer = RmsPropConfig::new()
        .with_alpha(config.rmsprop_alpha)
        .with_momentum(config.rmsprop_momentum)
        .with_epsilon(config.rmsprop_epsilon)
        .init();

    let mut training = SupervisedTraining::new(out, loader_train, loader_valid)
        .metric_train_numeric(LossMetric::new())
        .metric_valid_numeric(LossMetric::new())
        .with_default_checkpointers()
        .early_stopping(MetricEarlyStoppingStrategy::new(
            &LossMetric::new(),
            Aggregate::Mean,
            Direction::Lowest,
            MetricSplit::Valid,
            StoppingCondition::NoImprovementSince {
                n_epochs: config.patience,
            },
        ))
        .num_epochs(config.epochs)
        .renderer(Box::new(crate::progress_renderer::TrainingDisplay::new()));
    // A baseline without a head logs nothing for it (rather than NaN or zero every epoch).
    let heads = config.model.heads();
    for quantity in Quantity::ALL.into_iter().filter(|q| q.applies_to(heads)) {
        training = training
            .metric_train_numeric(StepMetric::new(quantity))
            .metric_valid_numeric(StepMetric::new(quantity));
    }
    if let Some(epoch) = resume_from {
        eprintln!("resuming after epoch {epoch}");
        training = training.checkpoint(epoch);
    } else if request.resume {
        eprintln!("no complete checkpoint yet: starting from the first epoch");
    }
    let result = training.launch(Learner::new(trainee, optimizer, learning_rates(config)));
    if let Some(error) = result.error {
        bail!("training failed: {error}");
    }

    export_best(request, &device, started)
}

/// The learning rate of every parameter: `learning_rate`, and `force_head_learning_rate` for
/// H-Net's force head (matched by its parameters' path, which checkpoints keep).
fn learning_rates(config: &TrainingConfig) -> ModuleLrScheduler {
    let scheduler = ModuleLrScheduler::new(config.learning_rate);
    match (config.force_head_learning_rate, &config.model) {
        (Some(head), ModelSpec::Hnet(_)) => {
            scheduler.with_group(ParamGroup::from_predicate(HNet::FORCE_HEAD_PATH), head)
        }
        _ => scheduler,
    }
}

/// Per-epoch means of every logged metric, from burn-train's logs in the run folder.
pub fn epoch_metrics(run: &Path) -> anyhow::Result<Vec<EpochRow>> {
    let mut rows = Vec::new();
    for split in ["train", "valid"] {
        let dir = run.join(split);
        let Ok(entries) = std::fs::read_dir(&dir) else {
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
            for file in std::fs::read_dir(entry.path())?.filter_map(|e| e.ok()) {
                let file_name = file.file_name().to_string_lossy().into_owned();
                let Some(metric) = file_name.strip_suffix(".log") else {
                    continue;
                };
                if let Some(mean) = weighted_mean(&std::fs::read_to_string(file.path())?) {
                    values.insert(metric.to_string(), mean);
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

/// Mean of a burn-train metric log (`value,count` per line), weighted by count.
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

/// One epoch's metric means on one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EpochRow {
    /// Epoch number (from 1).
    pub epoch: usize,
    /// `train` or `valid`.
    pub split: String,
    /// Metric name to its mean.
    pub values: BTreeMap<String, f64>,
}

/// Writes `metrics.csv` and exports the checkpoint with the lowest validation loss as
/// `model.bpk`, with a provenance record.
fn export_best(request: &TrainRequest, device: &Device, started: Instant) -> anyhow::Result<()> {
    let out = &request.out;
    let rows = epoch_metrics(out)?;
    let names: Vec<String> = {
        let mut set = std::collections::BTreeSet::new();
        for row in &rows {
            set.extend(row.values.keys().cloned());
        }
        set.into_iter().collect()
    };
    let mut csv = format!("epoch,split,{}\n", names.join(","));
    for row in &rows {
        let values: Vec<String> = names
            .iter()
            .map(|n| row.values.get(n).map(|v| v.to_string()).unwrap_or_default())
            .collect();
        csv.push_str(&format!(
            "{},{},{}\n",
            row.epoch,
            row.split,
            values.join(",")
        ));
    }
    std::fs::write(out.join("metrics.csv"), csv)?;

    let available = checkpoint_epochs(out);
    let best = rows
        .iter()
        .filter(|r| r.split == "valid" && available.contains(&r.epoch))
        .filter_map(|r| r.values.get("Loss").map(|l| (r.epoch, *l)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .or_else(|| available.last().map(|e| (*e, f64::NAN)))
        .context("no checkpoint was written")?;
    let config = &request.config;
    let record = burn::store::ModuleRecord::load(
        out.join("checkpoint").join(format!("model-{}.bpk", best.0)),
    )
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let net = config.model.init(device).map_err(anyhow::Error::msg)?;
    let trainee = StereoTrainee::new(net, &config.model, config.loss.clone())
        .try_load_record(record)
        .map_err(|e| anyhow::anyhow!("checkpoint of epoch {}: {e}", best.0))?;
    let provenance = BTreeMap::from([
        ("command".to_string(), request.command.clone()),
        ("data".to_string(), request.data.display().to_string()),
        ("config".to_string(), config.name.clone()),
        ("seed".to_string(), config.seed.to_string()),
        ("best_epoch".to_string(), best.0.to_string()),
        ("valid_loss".to_string(), best.1.to_string()),
        ("backend".to_string(), request.backend.name().to_string()),
        (
            "train_seconds_this_session".to_string(),
            format!("{:.0}", started.elapsed().as_secs_f64()),
        ),
    ]);
    let bytes = trainee
        .net
        .to_weights_bytes(&config.model, &provenance)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    hnet_model::weights::write_atomically(&out.join("model.bpk"), &bytes)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    eprintln!(
        "best epoch {} (validation loss {:.4}); weights in {}",
        best.0,
        best.1,
        out.join("model.bpk").display()
    );
    Ok(())
}

/// `hnet train` arguments.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Dataset folder (`hnet simulate`, `hnet import` or the app's export).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Run folder for checkpoints, logs and the final `model.bpk`.
    #[arg(long)]
    out: PathBuf,
    /// Settings: `cpu` (the default, sized for a 2-core machine), `paper` (the paper's full
    /// scale), or a JSON file in the same form (see configs/).
    #[arg(long, default_value = "cpu")]
    config: String,
    /// Train this architecture instead of the config's (`hnet`, `unet`, `fcn`, `hrnet`, `ynet`),
    /// with its default settings.
    #[arg(long)]
    architecture: Option<String>,
    /// Override the number of epochs.
    #[arg(long)]
    epochs: Option<usize>,
    /// Override the config's seed (weight initialisation and shuffling), e.g. to repeat a run and
    /// measure its spread.
    #[arg(long)]
    seed: Option<u64>,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// Continue the run in `--out` from its last complete checkpoint (settings and data as saved
    /// there).
    #[arg(long)]
    resume: bool,
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

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    if args.resume {
        let config = TrainingConfig::load(&args.out.join("config.json"))
            .with_context(|| format!("--resume: '{}' holds no run", args.out.display()))?;
        let data = match &args.data {
            Some(d) => d.clone(),
            None => crate::evaluation::run_data(&args.out)?,
        };
        return train(&TrainRequest {
            data,
            out: args.out.clone(),
            config,
            backend: args.backend,
            resume: true,
            command,
        });
    }
    let mut config = match builtin_config(&args.config) {
        Some(c) => c,
        None => TrainingConfig::load(Path::new(&args.config))?,
    };
    if let Some(name) = &args.architecture {
        let mut spec = ModelSpec::default_for(name).with_context(|| {
            format!("unknown architecture `{name}` (hnet, unet, fcn, hrnet, ynet)")
        })?;
        if let ModelSpec::Hnet(c) = &mut spec {
            *c = c.clone().with_image_size(config.image_size);
        }
        config.model = spec;
        config.name = format!("{}-{name}", config.name);
    }
    if let Some(epochs) = args.epochs {
        config.epochs = epochs;
    }
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    let data = args
        .data
        .clone()
        .context("--data is required (unless --resume)")?;
    train(&TrainRequest {
        data,
        out: args.out.clone(),
        config,
        backend: args.backend,
        resume: false,
        command,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::{ModuleVisitor, Param};

    /// Collects each float parameter's path, joined as Burn's optimiser joins it.
    #[derive(Default)]
    struct Paths {
        stack: Vec<String>,
        found: Vec<(burn::module::ParamId, String)>,
    }

    impl ModuleVisitor for Paths {
        fn enter_module(&mut self, name: &str, _container: &str) {
            self.stack.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container: &str) {
            self.stack.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.found.push((param.id, self.stack.join(".")));
        }
    }

    #[test]
    fn every_checked_in_config_loads() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
        let mut names = Vec::new();
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "json") {
                let config = TrainingConfig::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
                names.push(config.name);
            }
        }
        names.sort();
        assert_eq!(names, ["cpu", "cpu-ynet", "paper"]);
    }

    #[test]
    fn the_force_head_alone_gets_its_own_learning_rate() {
        let mut config = builtin_config("cpu").unwrap();
        config.model = ModelSpec::Hnet(hnet_model::HNetConfig::new().with_image_size([32, 32]));
        config.learning_rate = 1e-3;
        config.force_head_learning_rate = Some(1e-4);
        let device = Device::flex();
        let net = config.model.init(&device).unwrap();
        let trainee = StereoTrainee::new(net, &config.model, config.loss.clone());
        let mut paths = Paths::default();
        trainee.visit(&mut paths);
        let rates = learning_rates(&config).step();
        let mut head = 0;
        for (id, path) in &paths.found {
            let lr = rates.lr_from_param(*id, Some(path));
            let in_head = path.contains(".force.");
            assert_eq!(lr, if in_head { 1e-4 } else { 1e-3 }, "{path}");
            head += usize::from(in_head);
        }
        // Three dense layers, weights and biases.
        assert_eq!(head, 6);
        assert!(paths.found.len() > 50);
    }
}
