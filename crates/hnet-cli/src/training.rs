//! `hnet train`: H-Net (or a baseline) on a dataset with Burn's `burn-train` learner.
//!
//! RMSprop at the paper's learning rate, per-epoch checkpoints, early stopping on the validation
//! loss, the best checkpoint exported as the run's `model.bpk`. A run killed at any moment resumes
//! from its last complete checkpoint with `--resume`; a checkpoint or `model.bpk` that cannot be
//! written (a full disk) stops the run naming the file, and leaves the last complete checkpoint
//! for `--resume` ([`checkpoints`]). The settings are [`crate::config`]'s, the
//! run folder's files [`crate::run_dir`]'s; here the loop, with the network and its loss in
//! [`trainee`] and what is logged in [`metrics`].

mod checkpoints;
mod metric_log;
pub mod metrics;
mod stopping;
mod trainee;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use burn::data::dataloader::{DataLoader, DataLoaderBuilder};
use burn::module::{Module, ParamGroup};
use burn::optim::lr_scheduler::LrSchedulerConfig;
use burn::optim::lr_scheduler::cosine::CosineAnnealingLrSchedulerConfig;
use burn::optim::lr_scheduler::module_lr_scheduler::{ModuleLrScheduler, ModuleLrSchedulerConfig};
use burn::tensor::Device;
use burn::train::metric::LossMetric;
use burn::train::metric::store::{Aggregate, Direction, Split as MetricSplit};
use burn::train::{
    Interrupter, Learner, MetricEarlyStoppingStrategy, StoppingCondition, SupervisedTraining,
};
use hnet_model::HNet;
use hnet_model::architectures::{ModelSpec, StereoModel};
use hnet_model::model::ForceScale;
use hnet_model::training::{RmsPropSettings, TrainingBatch};
use hnet_twin::dataset::{Dataset, Split};
use hnet_twin::model_facts::{ForceDomain, ModelFacts, recorded_name};

use self::checkpoints::{RunCheckpointer, WriteFailure};
use self::metric_log::RunMetricLogger;
use self::metrics::{Quantity, StepMetric};
use self::stopping::{StoppingRule, TimeBudget, non_finite_epochs, parse_duration};
use self::trainee::StereoTrainee;
use crate::backend::BackendChoice;
use crate::config::{DEFAULT_MAX_MEMORY_MIB, LearningRateSchedule, TrainingConfig, builtin_config};
use crate::data::twin_stream::{EpochCounting, TwinStream};
use crate::data::{DiskSplit, StereoBatcher, StereoSplit, force_label_admitted, pair_bytes};
use crate::run_dir::{LOSS_METRIC, RunDir, RunInfo, log_name};

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
    /// Stop at the end of the last epoch that fits in this much wall-clock time (from the
    /// start of this session's training, data loading included).
    pub time_budget: Option<Duration>,
}

/// Runs (or resumes) a training and writes the best model to `out/model.bpk`.
pub fn train(request: &TrainRequest) -> anyhow::Result<()> {
    let session_started = Instant::now();
    let run = RunDir::new(&request.out);
    // A new run fixes its force statistics now, so that config.json records them.
    let resolved;
    let request = if request.resume {
        request
    } else {
        resolved = TrainRequest {
            config: with_force_statistics(request.config.clone(), &request.data)?,
            ..request.clone()
        };
        &resolved
    };
    let config = &request.config;
    config.check()?;
    let dataset = Dataset::open(&request.data)?;
    let resume_from = if request.resume {
        let saved = run
            .read_config()
            .with_context(|| format!("--resume: no run to resume in '{}'", run.root().display()))?;
        if &saved != config {
            bail!(
                "--resume: the run in '{}' was started with other settings",
                run.root().display()
            );
        }
        run.last_readable_checkpoint()?
    } else {
        if !run.is_empty()? {
            bail!(
                "run folder '{}' is not empty: choose another --out, or pass --resume to continue it",
                run.root().display()
            );
        }
        None
    };
    // Everything that can refuse the data refuses it before a new run folder exists.
    let stream = config
        .stream
        .as_ref()
        .map(|stream| {
            TwinStream::new(
                stream,
                &dataset,
                config.image_size,
                resume_from.unwrap_or(0),
            )
        })
        .transpose()?;
    let started = Instant::now();
    let load = |split: Split, limit: Option<usize>| -> anyhow::Result<StereoSplit> {
        let pairs = StereoSplit::load(&dataset, split, config.image_size, limit)?;
        if pairs.items.is_empty() {
            bail!(
                "{} needs pairs in its {} split",
                request.data.display(),
                split.name()
            );
        }
        Ok(pairs)
    };
    let labels = config.label_filter()?;
    // Force labels the config leaves out (a model's estimates, by default) train masks only.
    let admit = |split: &mut StereoSplit, name: &str| {
        let left_out = split.admit_force_labels(&dataset, &labels);
        if left_out > 0 {
            eprintln!(
                "{left_out} {name} pair(s) train their masks only: their force labels are not \
                 among the origins learnt from ({}; `--labels all` learns them all)",
                labels.words()
            );
        }
    };
    let mut valid_split = load(Split::Val, config.max_valid_samples)?;
    admit(&mut valid_split, "validation");
    if let Some(path) = &config.init_weights
        && !request.resume
    {
        check_initial_spec(path, &config.model)?;
    }
    if !request.resume {
        std::fs::create_dir_all(run.root())
            .with_context(|| format!("cannot create run folder '{}'", run.root().display()))?;
        run.write_config(config)?;
    }
    run.write_info(&RunInfo {
        // Absolute, so that `hnet eval` and `hnet report` find it from any folder.
        data: std::fs::canonicalize(&request.data).unwrap_or_else(|_| request.data.clone()),
        backend: request.backend.name().into(),
        command: request.command.clone(),
    })?;

    let device: Device = request.backend.device()?;
    device.seed(config.seed);
    let batcher = StereoBatcher {
        size: config.image_size,
    };
    let builder = || {
        DataLoaderBuilder::new(batcher.clone())
            .batch_size(config.batch_size)
            .num_workers(config.num_workers)
    };
    let (loader_train, train_pairs): (Arc<dyn DataLoader<TrainingBatch>>, usize) = match stream {
        Some(twin) => {
            let epochs_started = twin.epochs_started();
            let pairs = twin.pairs_per_epoch();
            eprintln!("training on {}", twin.describe());
            let loader = builder()
                .shuffle(config.seed)
                .set_device(device.clone().autodiff())
                .build(twin);
            (Arc::new(EpochCounting::new(loader, epochs_started)), pairs)
        }
        None => {
            let limit = config.max_train_samples;
            let pairs = dataset
                .split(Split::Train)
                .take(limit.unwrap_or(usize::MAX))
                .count();
            let budget_mib = config.max_memory_mib.unwrap_or(DEFAULT_MAX_MEMORY_MIB);
            let decoded_mib = (pairs * pair_bytes(config.image_size)).div_ceil(1 << 20);
            let builder = builder()
                .shuffle(config.seed)
                .set_device(device.clone().autodiff());
            if pairs > 0 && decoded_mib > budget_mib {
                eprintln!(
                    "reading {pairs} training pairs at {} from disk batch by batch ({decoded_mib} \
                     MiB decoded would exceed max_memory_mib {budget_mib})",
                    config.image_size
                );
                let split = DiskSplit::new(&dataset, Split::Train, config.image_size, limit)
                    .with_labels(labels.clone());
                (builder.build(split), pairs)
            } else {
                let mut train_split = load(Split::Train, limit)?;
                admit(&mut train_split, "training");
                let pairs = train_split.items.len();
                eprintln!("loaded {pairs} training pairs at {}", config.image_size);
                (builder.build(train_split), pairs)
            }
        }
    };
    eprintln!(
        "loaded {} validation pairs at {} in {:.1} s",
        valid_split.items.len(),
        config.image_size,
        started.elapsed().as_secs_f64()
    );
    let loader_valid = builder().set_device(device.clone()).build(valid_split);

    let net = match &config.init_weights {
        // A run resumed from a checkpoint loads it over whatever it starts from; one stopped
        // before its first checkpoint starts again from its initial weights.
        Some(path) if resume_from.is_none() => {
            let bytes = std::fs::read(path).with_context(|| {
                format!(
                    "init_weights: cannot read weights file '{}'",
                    path.display()
                )
            })?;
            let source = path.display().to_string();
            StereoModel::from_weights_bytes(&bytes, &device.clone().autodiff(), &source)?.0
        }
        _ => config
            .model
            .init(&device.clone().autodiff())
            .map_err(anyhow::Error::msg)?,
    };
    let interrupter = Interrupter::new();
    let trainee = StereoTrainee::new(net, &config.model, config.loss.clone())
        .stopping_on_divergence(interrupter.clone());
    let optimizer = RmsPropSettings {
        alpha: config.rmsprop_alpha,
        momentum: config.rmsprop_momentum,
        epsilon: config.rmsprop_epsilon,
    }
    .init();

    // Checkpoints written atomically, the last complete one never deleted, a failed write named.
    let write_failure = WriteFailure::default();
    let [model_parts, optim_parts, scheduler_parts] =
        RunCheckpointer::for_run(&run, &write_failure);
    let mut training = SupervisedTraining::new(run.root(), loader_train, loader_valid)
        .metric_train_numeric(LossMetric::new())
        .metric_valid_numeric(LossMetric::new())
        .with_custom_checkpointers(model_parts, optim_parts, scheduler_parts)
        // burn-train's own file logger panics on a failed write; this one names the file.
        .with_metric_logger(RunMetricLogger::new(run.root(), &write_failure))
        .early_stopping(StoppingRule::new(
            MetricEarlyStoppingStrategy::new(
                &LossMetric::new(),
                Aggregate::Mean,
                Direction::Lowest,
                MetricSplit::Valid,
                StoppingCondition::NoImprovementSince {
                    n_epochs: config.patience,
                },
            ),
            request
                .time_budget
                .map(|limit| TimeBudget::new(limit, session_started, Instant::now())),
            &write_failure,
        ))
        .with_interrupter(interrupter)
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
        match &config.init_weights {
            Some(path) => eprintln!(
                "no complete checkpoint yet: starting from the first epoch, from the initial \
                 weights '{}'",
                path.display()
            ),
            None => eprintln!("no complete checkpoint yet: starting from the first epoch"),
        }
    }
    let iterations_per_epoch = train_pairs.div_ceil(config.batch_size.max(1));
    let rates = learning_rates(config, iterations_per_epoch * config.epochs)?;
    let result = training.launch(Learner::new(trainee, optimizer, rates));
    if let Some(failure) = write_failure.get() {
        bail!("{failure}\n{}", resume_advice(&run, false));
    }
    if let Some(error) = result.error {
        bail!("training failed: {error}");
    }
    if let Some(reason) = result.interrupted.and_then(|i| i.reason) {
        eprintln!("stopping in the middle of an epoch: {reason}");
    }
    // A diverged epoch's checkpoint is set aside (an epoch stopped at its diverged step has
    // none): `--resume` and the export use the ones before.
    for epoch in non_finite_epochs(&run.epoch_metrics()?) {
        if run.set_aside_checkpoint(epoch)? {
            eprintln!("epoch {epoch}'s loss was not finite: its checkpoint is set aside");
        } else {
            eprintln!("epoch {epoch}'s loss was not finite: it was stopped before its checkpoint");
        }
    }

    export_best(request, &run, &device, started)
}

/// What to do after a checkpoint (or, when `exporting`, `model.bpk`) could not be
/// written: `--resume` continues from the run's last complete checkpoint once the disk has room.
fn resume_advice(run: &RunDir, exporting: bool) -> String {
    let resume = format!("`hnet train --resume --out {}`", run.root().display());
    let writable = "once the run folder can be written (free disk space?)";
    match (run.checkpoint_epochs().last(), exporting) {
        (Some(epoch), false) => format!(
            "training stopped; epoch {epoch}'s checkpoint is complete: {writable}, {resume} \
             continues from it"
        ),
        (Some(epoch), true) => format!(
            "the checkpoints are kept (the last, epoch {epoch}'s, is complete): {writable}, \
             {resume} writes model.bpk from them"
        ),
        (None, _) => format!(
            "training stopped before any checkpoint was complete: {writable}, {resume} starts \
             again from the first epoch"
        ),
    }
}

/// The learning rate of every parameter: `learning_rate`, and `force_head_learning_rate` for
/// H-Net's force head (matched by its parameters' path, which checkpoints keep), each following
/// the config's schedule over the run's `iterations`.
fn learning_rates(config: &TrainingConfig, iterations: usize) -> anyhow::Result<ModuleLrScheduler> {
    let rate = |lr: f64| -> LrSchedulerConfig {
        match config.schedule {
            LearningRateSchedule::Constant => LrSchedulerConfig::Constant(lr),
            LearningRateSchedule::Cosine { final_factor } => {
                CosineAnnealingLrSchedulerConfig::new(lr, iterations.max(1))
                    .with_min_lr(lr * final_factor.clamp(0.0, 1.0))
                    .into()
            }
        }
    };
    let mut scheduler = ModuleLrSchedulerConfig::new(rate(config.learning_rate));
    if let (Some(head), ModelSpec::Hnet(_)) = (config.force_head_learning_rate, &config.model) {
        scheduler = scheduler.with_group(
            ParamGroup::from_predicate(HNet::FORCE_HEAD_PATH),
            rate(head),
        );
    }
    scheduler
        .init()
        .map_err(|e| anyhow::anyhow!("learning rate schedule: {e}"))
}

/// `config` with H-Net's force statistics filled in from the train split of `data` when it asks
/// for standardised forces (the baselines ignore the setting). Statistics already in the
/// config are kept.
fn with_force_statistics(
    mut config: TrainingConfig,
    data: &Path,
) -> anyhow::Result<TrainingConfig> {
    let labels = config.label_filter()?;
    let ModelSpec::Hnet(network) = &mut config.model else {
        return Ok(config);
    };
    if !config.standardise_force || network.force_scale.is_some() {
        return Ok(config);
    }
    // A second stage keeps the force statistics its starting network was trained with.
    if let Some(path) = &config.init_weights
        && let ModelSpec::Hnet(start) = initial_spec(path)?
        && let Some(scale) = start.force_scale
    {
        network.force_scale = Some(scale);
        config.loss.force_std_n = Some(scale.std_n);
        return Ok(config);
    }
    let dataset = Dataset::open(data)?;
    // Of the labels the head learns from only.
    let learnt = dataset
        .split(Split::Train)
        .filter(|row| force_label_admitted(row, &labels))
        .map(|row| row.force_n);
    let scale = ForceScale::of(learnt).with_context(|| {
        format!(
            "standardise_force: the train split of {} needs at least two pairs whose force \
             labels are learnt from ({}), with forces that vary on every axis",
            data.display(),
            labels.words()
        )
    })?;
    network.force_scale = Some(scale);
    config.loss.force_std_n = Some(scale.std_n);
    Ok(config)
}

/// The settings of the network in the weights file `path` (its header only).
fn initial_spec(path: &Path) -> anyhow::Result<ModelSpec> {
    let source = path.display().to_string();
    let bytes = std::fs::read(path)
        .with_context(|| format!("init_weights: cannot read weights file '{source}'"))?;
    let header = hnet_model::weights::read_header(&bytes, &source)?;
    ModelSpec::from_settings_json(&header.architecture, &header.config_json).map_err(|e| {
        anyhow::anyhow!("init_weights: weights file '{source}' has unreadable settings: {e}")
    })
}

/// Refuses a weights file `path` whose network is not `expected`'s (architecture, settings and
/// force statistics; H-Net's input size may differ, [`ModelSpec::carries_over_to`]): a recipe's
/// next stage starts from it. Says so when the stage changes the input size.
fn check_initial_spec(path: &Path, expected: &ModelSpec) -> anyhow::Result<()> {
    let spec = initial_spec(path)?;
    if !spec.carries_over_to(expected) {
        bail!(
            "init_weights: weights file '{}' holds another network than the config's (its \
             settings: {}; the config's: {})",
            path.display(),
            serde_json::to_string(&spec).unwrap_or_default(),
            serde_json::to_string(expected).unwrap_or_default()
        );
    }
    if let (ModelSpec::Hnet(start), ModelSpec::Hnet(goal)) = (&spec, expected)
        && start.image_size != goal.image_size
    {
        eprintln!(
            "init_weights: '{}' was trained at {}; its weights go on training at {} (H-Net's \
             parameters do not depend on the input size)",
            path.display(),
            start.image_size,
            goal.image_size
        );
    }
    Ok(())
}

/// Writes `metrics.csv` and exports the checkpoint with the lowest validation loss as
/// `model.bpk`, with a provenance record.
fn export_best(
    request: &TrainRequest,
    run: &RunDir,
    device: &Device,
    started: Instant,
) -> anyhow::Result<()> {
    let rows = run.epoch_metrics()?;
    let names: Vec<String> = {
        let mut set = std::collections::BTreeSet::new();
        for row in &rows {
            set.extend(row.values.keys().cloned());
        }
        set.into_iter().collect()
    };
    let header: Vec<String> = names.iter().map(|n| log_name(n)).collect();
    let mut csv = format!("epoch,split,{}\n", header.join(","));
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
    let metrics_file = run.metrics_file();
    std::fs::write(&metrics_file, csv)
        .with_context(|| format!("cannot write '{}'", metrics_file.display()))?;

    let available = run.checkpoint_epochs();
    let best = rows
        .iter()
        .filter(|r| r.split == "valid" && available.contains(&r.epoch))
        .filter_map(|r| r.values.get(LOSS_METRIC).map(|l| (r.epoch, *l)))
        .filter(|(_, loss)| loss.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .or_else(|| available.last().map(|e| (*e, f64::NAN)))
        .with_context(|| {
            format!(
                "no usable checkpoint in '{}': none was written, or every epoch's loss was not \
                 finite",
                run.root().display()
            )
        })?;
    let config = &request.config;
    let checkpoint = run.checkpoint_model_file(best.0);
    let record = burn::store::ModuleRecord::load(&checkpoint)
        .map_err(|e| anyhow::anyhow!("checkpoint '{}': {e}", checkpoint.display()))?;
    let net = config.model.init(device).map_err(anyhow::Error::msg)?;
    let trainee = StereoTrainee::new(net, &config.model, config.loss.clone())
        .try_load_record(record)
        .map_err(|e| anyhow::anyhow!("checkpoint '{}': {e}", checkpoint.display()))?;
    let mut provenance = BTreeMap::from([
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
    // The data the force head learned from (a stream's bench pairs come from the dataset's own
    // twin settings; its off-bench pairs teach masks only): what the page's verdict compares a
    // pair with (hnet_twin::model_facts).
    let force_domain = Dataset::open(&request.data).ok().and_then(|dataset| {
        ForceDomain::of_twin_source(&recorded_name(&request.data), &dataset.header.source)
    });
    ModelFacts {
        force_domain,
        measured: None,
    }
    .write(&mut provenance);
    let bytes = trainee
        .net
        .to_weights_bytes(&config.model, &provenance)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    // Atomically (a temporary file beside it, renamed over it): a failed write leaves the
    // previous model.bpk, and the checkpoints, as they were.
    let model_file = run.model_file();
    hnet_twin::dataset::files::write_atomically(&model_file, &bytes).map_err(|e| {
        anyhow::anyhow!(
            "cannot write '{}': {e}\n{}",
            model_file.display(),
            resume_advice(run, true)
        )
    })?;
    eprintln!(
        "best epoch {} (validation loss {:.4}); weights in {}",
        best.0,
        best.1,
        run.model_file().display()
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
    /// Override the seed of the config's stream of fresh twin pairs (`stream.seed`): with
    /// `--seed`, a repeat that trains on other pairs as well as in another order.
    #[arg(long)]
    stream_seed: Option<u64>,
    /// Start from the network in this weights file (the config's network, its force statistics
    /// included; an H-Net may come from another input size) instead of a random
    /// initialisation: a recipe's next stage.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// Continue the run in `--out` from its last complete checkpoint (settings and data as saved
    /// there).
    #[arg(long)]
    resume: bool,
    /// Stop cleanly at the end of the last epoch that fits in this wall-clock time (`90s`,
    /// `12m`, `1h30m`), keeping the best checkpoint; `--resume` continues such a run.
    #[arg(long, value_parser = parse_duration)]
    time_budget: Option<Duration>,
    /// The force labels the force head learns from, by origin (the manifest's `label_origin`):
    /// `all`, or a comma-separated list of measured, typed, imported, simulated, estimate and
    /// unrecorded. Default: all but `estimate` (labels copied from a model's estimate). Pairs
    /// left out still train the masks.
    #[arg(long)]
    labels: Option<String>,
}

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let command = crate::command_line();
    if args.resume {
        let run = RunDir::new(&args.out);
        let config = run
            .read_config()
            .with_context(|| format!("--resume: '{}' holds no run", args.out.display()))?;
        let data = match &args.data {
            Some(d) => d.clone(),
            None => run.read_info()?.data,
        };
        return train(&TrainRequest {
            data,
            out: args.out.clone(),
            config,
            backend: args.backend,
            resume: true,
            command,
            time_budget: args.time_budget,
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
    if let Some(seed) = args.stream_seed {
        let stream = config
            .stream
            .as_mut()
            .context("--stream-seed needs a config with a `stream` of twin pairs")?;
        stream.seed = seed;
    }
    if let Some(init) = &args.init {
        config.init_weights = Some(init.clone());
    }
    if let Some(labels) = &args.labels {
        config.force_labels = Some(labels.clone());
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
        time_budget: args.time_budget,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::{ModuleVisitor, Param};
    use burn::tensor::Tensor;

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
    fn the_force_head_alone_gets_its_own_learning_rate() {
        let mut config = builtin_config("cpu").unwrap();
        config.model = ModelSpec::Hnet(
            hnet_model::HNetConfig::new().with_image_size(hnet_units::ImageSize::square(32)),
        );
        config.learning_rate = 1e-3;
        config.force_head_learning_rate = Some(1e-4);
        let device = Device::flex();
        let net = config.model.init(&device).unwrap();
        let trainee = StereoTrainee::new(net, &config.model, config.loss.clone());
        let mut paths = Paths::default();
        trainee.visit(&mut paths);
        let rates = learning_rates(&config, 100).unwrap().step();
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
