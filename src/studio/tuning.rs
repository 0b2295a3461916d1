//! "Fine-tune on my pairs" on the page's state: the fine-tuning workers driven step by step, its
//! progress, the result kept or discarded, and the kept weights chosen in the model bar. Where
//! the network runs on WebGPU (its start-up check passed), one WebGPU worker trains
//! (crates/hnet-gpu, which carries crates/hnet-tune's exports); otherwise the CPU workers
//! (crates/hnet-tune, one [`ModuleWorker`] per core, at most the batch), each step split between
//! them and the average of their gradients relayed to each ([`hnet_model::fine_tune::Share`]).
//! Should WebGPU not start for the fine-tune, the CPU workers train, and the page says why.
//! Nothing is stored until the user keeps a result: a tab closed or a run stopped midway leaves
//! the weights in use, and those kept before, as they were.

use std::rc::Rc;

use hnet_model::fine_tune::{EpochReport, FineTuneSettings, FinishReason, HeldBackScores};
use js_sys::{Array, Float32Array, Uint8Array};
use leptos::prelude::*;
use wasm_bindgen::JsCast;
use wasm_bindgen::JsValue;

use super::{ModelState, Studio, load_model};
use crate::browser::now_ms;
use crate::browser::yield_to_browser;
use crate::compute::Backend;
use crate::cpu_pool::pool_size;
use crate::engine::WeightsOrigin;
use crate::error_text::with_causes;
use crate::fine_tune::{
    REFERENCE_PAIRS, REFERENCE_SEED, REHEARSAL_PAIRS, REHEARSAL_SEED, TuningDevice, TuningSet,
    TwinDomainSampler, kept_provenance, seconds_left, tuning_set,
};
use crate::gpu_worker::START_TIMEOUT_S;
use crate::imaging::WORK_SIZE;
use crate::module_worker::{ModuleWorker, ModuleWorkerError, within};
use crate::storage::{self, KeptWeights};
use crate::{browser, page_query};
use hnet_twin::model_facts::ForceDomain;
use hnet_twin::model_facts::ModelFacts;
use hnet_twin::simulator::carm::CArm;
use hnet_twin::simulator::scene::{Backgrounds, TwinError};
use hnet_twin::simulator::synthetic_xray::BackgroundSource;

/// The kept weights' file name.
pub const KEPT_NAME: &str = "hnet-fine-tuned.bpk";

/// Where a fine-tune stands.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum TuningState {
    /// None running, none to keep.
    #[default]
    Idle,
    /// Running.
    Running(TuningProgress),
    /// Ended: the before/after table and the weights to keep, if an epoch improved.
    Ended(TuningResult),
}

/// A running fine-tune's progress.
#[derive(Debug, Clone, PartialEq)]
pub struct TuningProgress {
    /// Pairs trained on and held back, and those with a force label.
    pub split: (usize, usize),
    /// Where the steps run: WebGPU, or the CPU workers each step is split between.
    pub device: TuningDevice,
    /// Pairs in the set, and of them with a force label.
    pub pairs: usize,
    /// Twin pairs rehearsed beside them (counted in `split`'s trained-on pairs).
    pub rehearsed: usize,
    /// Pairs with a force label.
    pub with_force: usize,
    /// Steps done and steps in the whole run (at most `max_epochs`).
    pub steps: (usize, usize),
    /// Most epochs.
    pub max_epochs: usize,
    /// Steps per epoch.
    pub steps_per_epoch: usize,
    /// The held-back scores of the starting network, once measured.
    pub before: Option<HeldBackScores>,
    /// The epochs done.
    pub epochs: Vec<EpochReport>,
    /// Pairs trained per second so far.
    pub pairs_per_s: Option<f64>,
    /// Seconds left if every epoch runs (early stopping may end it sooner).
    pub seconds_left: Option<f64>,
}

/// An ended fine-tune.
#[derive(Debug, Clone, PartialEq)]
pub struct TuningResult {
    /// Pairs trained on and held back.
    pub split: (usize, usize),
    /// The starting network on the held-back pairs.
    pub before: HeldBackScores,
    /// And on the reference twin pairs of the weights' own domain, when it is known.
    pub before_reference: Option<HeldBackScores>,
    /// The best epoch, if one improved on the held-back loss.
    pub best: Option<EpochReport>,
    /// Every epoch done.
    pub epochs: Vec<EpochReport>,
    /// Why it ended: `None` when the user stopped it.
    pub reason: Option<FinishReason>,
    /// The best epoch's weights file.
    pub weights: Option<Rc<[u8]>>,
}

/// The fine-tune's state: the run and its workers, and the weights kept from an earlier one.
#[derive(Clone, Copy)]
pub struct TuningStore {
    /// The fine-tune running or ended.
    pub state: RwSignal<TuningState, LocalStorage>,
    /// Its workers, while it runs (the first scores the epochs and holds the best weights).
    workers: StoredValue<Vec<Rc<ModuleWorker>>, LocalStorage>,
    /// The fine-tuned weights kept in the browser, if any.
    pub kept: RwSignal<Option<Rc<KeptWeights>>, LocalStorage>,
}

impl TuningStore {
    /// No fine-tune, nothing kept (until the browser's storage is read).
    pub fn new() -> Self {
        Self {
            state: RwSignal::new_local(TuningState::Idle),
            workers: StoredValue::new_local(Vec::new()),
            kept: RwSignal::new_local(None),
        }
    }
}

impl Default for TuningStore {
    fn default() -> Self {
        Self::new()
    }
}

impl Studio {
    /// Starts fine-tuning the loaded network on the page's labelled pairs with `settings`, in
    /// workers of its own, one per core (at most the batch), each step split between them; with
    /// `rehearse`, on twin pairs of the weights' own domain too (when their file records it).
    /// Says why when it cannot.
    pub fn start_tuning(&self, settings: FineTuneSettings, rehearse: bool) {
        if matches!(self.tuning.state.get_untracked(), TuningState::Running(_)) {
            return;
        }
        let ModelState::Ready(engine) = self.network.model.get_untracked() else {
            self.notices.error("Fine-tuning needs a loaded network");
            return;
        };
        let set = match self
            .pairs
            .workspace
            .with_untracked(|ws| tuning_set(&ws.pairs, engine.input))
        {
            Ok(set) => set,
            Err(why) => {
                self.notices.error(format!("Cannot fine-tune: {why}"));
                return;
            }
        };
        // Twin pairs of the weights' own domain, scored beside the held-back pairs.
        let domain = engine
            .header
            .as_ref()
            .and_then(|h| ModelFacts::read(&h.provenance).ok())
            .and_then(|facts| facts.force_domain);
        // WebGPU where the network runs on it; otherwise one CPU worker per core, at most one
        // per pair of the batch.
        let on_webgpu = engine.backend == Backend::WebGpu;
        let spawned = if on_webgpu {
            ModuleWorker::spawn("hnet-gpu", WEBGPU_WORKER).map(|w| vec![Rc::new(w)])
        } else {
            cpu_workers(settings.batch_size)
        };
        let workers = match spawned {
            Ok(workers) => workers,
            Err(e) => {
                self.notices
                    .error(format!("Cannot fine-tune: {}", with_causes(&e)));
                return;
            }
        };
        let device = if on_webgpu {
            TuningDevice::WebGpu
        } else {
            TuningDevice::Cpu {
                workers: workers.len(),
            }
        };
        let settings = FineTuneSettings {
            patience: page_query::tune_patience(&browser::page_query())
                .unwrap_or(settings.patience),
            ..settings
        };
        self.tuning.workers.set_value(workers.clone());
        let studio = *self;
        let (start_name, start_provenance) = (
            engine.weights_name.clone(),
            engine
                .header
                .as_ref()
                .map(|h| h.provenance.clone())
                .unwrap_or_default(),
        );
        self.tuning.state.set(TuningState::Running(TuningProgress {
            split: (0, 0),
            device,
            pairs: set.pairs,
            rehearsed: 0,
            with_force: set.with_force,
            steps: (0, 0),
            max_epochs: settings.max_epochs,
            steps_per_epoch: 0,
            before: None,
            epochs: Vec::new(),
            pairs_per_s: None,
            seconds_left: None,
        }));
        leptos::task::spawn_local(async move {
            // WebGPU set up in its worker, or the CPU workers instead, saying why.
            let Some((workers, device)) =
                ready_workers(studio, workers, device, settings.batch_size).await
            else {
                return;
            };
            let settings = FineTuneSettings {
                replicas: device.replicas(),
                ..settings
            };
            // The twin pairs are drawn one at a time, the browser answering in between.
            let (reference, rehearsal) = match twin_pairs(domain.as_ref(), rehearse).await {
                Ok(sets) => sets,
                Err(e) => {
                    stop_all(&workers, "the fine-tune did not start");
                    studio.tuning.workers.set_value(Vec::new());
                    studio.tuning.state.set(TuningState::Idle);
                    studio.notices.error(format!(
                        "Cannot fine-tune: the twin pairs of the weights' domain: {e}"
                    ));
                    return;
                }
            };
            let rehearsed = rehearsal.as_ref().map_or(0, |r| r.pairs);
            studio.tuning.state.update(|state| {
                if let TuningState::Running(progress) = state {
                    progress.rehearsed = rehearsed;
                }
            });
            let start = TuningStart {
                weights: &engine.weights,
                name: &start_name,
                provenance: &start_provenance,
                set: &set,
                reference: reference.as_ref(),
                rehearsal: rehearsal.as_ref(),
                settings,
                device,
            };
            let outcome = run(studio, &workers, &start).await;
            stop_all(&workers, "the fine-tune is over");
            studio.tuning.workers.set_value(Vec::new());
            match outcome {
                Ok(result) => {
                    let said = match (result.reason, &result.best) {
                        (Some(FinishReason::Diverged), _) => {
                            "Fine-tuning diverged (a loss was not finite) and stopped; the model in use is unchanged"
                        }
                        (None, _) => "Fine-tuning stopped",
                        (_, None) => {
                            "Fine-tuning ended without improving on the held-back pairs; the model in use is unchanged"
                        }
                        (_, Some(_)) => "Fine-tuning ended: keep or discard the result",
                    };
                    if result.reason == Some(FinishReason::Diverged) {
                        studio.notices.error(said);
                    } else {
                        studio.notices.info(said);
                    }
                    studio.tuning.state.set(TuningState::Ended(result));
                }
                Err(e) => {
                    studio.tuning.state.set(TuningState::Idle);
                    studio.notices.error(format!(
                        "Fine-tuning failed: {}; the model in use is unchanged",
                        with_causes(&e)
                    ));
                }
            }
        });
    }

    /// Stops the running fine-tune: its best epoch so far, if any, can still be kept.
    pub fn stop_tuning(&self) {
        stop_all(&self.tuning.workers.get_value(), STOPPED_BY_USER);
    }

    /// Keeps the ended fine-tune's weights: stored in the browser, chosen, and loaded.
    pub fn keep_tuned(&self) {
        let TuningState::Ended(result) = self.tuning.state.get_untracked() else {
            return;
        };
        let Some(bytes) = result.weights else {
            return;
        };
        let studio = *self;
        leptos::task::spawn_local(async move {
            let kept = KeptWeights {
                name: KEPT_NAME.to_string(),
                bytes: bytes.to_vec(),
                chosen: true,
            };
            match storage::save_kept_weights(&kept).await {
                Ok(()) => {
                    studio.tuning.kept.set(Some(Rc::new(kept)));
                    studio.tuning.state.set(TuningState::Idle);
                    load_model(
                        studio,
                        Some((bytes, KEPT_NAME.to_string(), WeightsOrigin::FineTuned)),
                    );
                }
                // The result stays on the page (to retry or download); what was kept before
                // is untouched.
                Err(e) => studio.notices.error(format!(
                    "The fine-tuned weights could not be kept: {}",
                    with_causes(&e)
                )),
            }
        });
    }

    /// Discards the ended fine-tune.
    pub fn discard_tuned(&self) {
        self.tuning.state.set(TuningState::Idle);
        self.notices
            .info("Fine-tuned weights discarded; the model in use is unchanged");
    }

    /// Uses the kept fine-tuned weights (`true`) or the bundled ones, now and when the page
    /// opens next.
    pub fn choose_kept(&self, fine_tuned: bool) {
        let Some(kept) = self.tuning.kept.get_untracked() else {
            return;
        };
        let studio = *self;
        load_model(
            studio,
            fine_tuned.then(|| {
                (
                    Rc::<[u8]>::from(kept.bytes.as_slice()),
                    kept.name.clone(),
                    WeightsOrigin::FineTuned,
                )
            }),
        );
        leptos::task::spawn_local(async move {
            let chosen = KeptWeights {
                chosen: fine_tuned,
                ..(*kept).clone()
            };
            match storage::save_kept_weights(&chosen).await {
                Ok(()) => studio.tuning.kept.set(Some(Rc::new(chosen))),
                Err(e) => studio.notices.error(format!(
                    "The choice of weights could not be saved: {}",
                    with_causes(&e)
                )),
            }
        });
    }
}

/// Rows of the phantom rendered between two answers of the browser: an eighth of a view, about
/// 15 ms on the page's thread.
const PHANTOM_BAND_ROWS: usize = 64;

/// The built-in phantom seen from `view`: about 0.1 s of work on the page's thread, so rendered
/// a band of rows at a time, the browser answering in between.
async fn phantom_in_bands(view: &CArm) -> BackgroundSource {
    let mut bands = Backgrounds::phantom_view_in_bands(view);
    while bands.render_rows(PHANTOM_BAND_ROWS) {
        yield_to_browser().await;
    }
    BackgroundSource::of_phantom(view, bands)
}

/// The reference twin pairs of `domain` (when it is the twin's) and, with `rehearse`, the pairs
/// rehearsed, drawn one at a time with the browser answering in between.
async fn twin_pairs(
    domain: Option<&ForceDomain>,
    rehearse: bool,
) -> Result<(Option<TuningSet>, Option<TuningSet>), TwinError> {
    yield_to_browser().await;
    let Some(config) = domain.and_then(TwinDomainSampler::config) else {
        return Ok((None, None));
    };
    let a = phantom_in_bands(&config.views.a).await;
    let b = phantom_in_bands(&config.views.b).await;
    let sampler = TwinDomainSampler::with_backgrounds(config, Backgrounds::of_views(a, b));
    let mut sets = Vec::new();
    let wanted = [
        (REFERENCE_PAIRS, REFERENCE_SEED, true),
        (REHEARSAL_PAIRS, REHEARSAL_SEED, rehearse),
    ];
    for (count, seed, wanted) in wanted {
        if !wanted {
            sets.push(None);
            continue;
        }
        let mut set = TuningSet::empty();
        for index in 0..count as u64 {
            yield_to_browser().await;
            sampler.push(seed, index, &mut set)?;
        }
        sets.push(Some(set));
    }
    let rehearsal = sets.pop().flatten();
    Ok((sets.pop().flatten(), rehearsal))
}

/// What a fine-tune starts from.
#[derive(Clone, Copy)]
struct TuningStart<'a> {
    /// The weights file, its name and its provenance.
    weights: &'a [u8],
    name: &'a str,
    provenance: &'a std::collections::BTreeMap<String, String>,
    /// The pairs it learns from.
    set: &'a TuningSet,
    /// Twin pairs of the weights' own domain, scored only.
    reference: Option<&'a TuningSet>,
    /// Twin pairs of the weights' own domain, trained on too.
    rehearsal: Option<&'a TuningSet>,
    settings: FineTuneSettings,
    /// Where the steps run (`settings.replicas` is its replicas).
    device: TuningDevice,
}

/// The WebGPU fine-tuning worker's name in messages.
const WEBGPU_WORKER: &str = "the WebGPU fine-tuning worker";

/// The CPU fine-tuning workers: one per core, at most one per pair of a batch of `batch_size`;
/// the run goes on with those that started.
fn cpu_workers(batch_size: usize) -> Result<Vec<Rc<ModuleWorker>>, ModuleWorkerError> {
    let mut workers = Vec::new();
    for _ in 0..pool_size().clamp(1, batch_size.max(1)) {
        match ModuleWorker::spawn("hnet-tune", "the fine-tuning worker") {
            Ok(worker) => workers.push(Rc::new(worker)),
            Err(e) if workers.is_empty() => return Err(e),
            Err(_) => break,
        }
    }
    Ok(workers)
}

/// The workers a fine-tune on `device` runs on, ready: on WebGPU, `workers` (its one worker) once
/// WebGPU is set up in it; should WebGPU not start there, the CPU workers instead (steps of
/// `batch_size` pairs), the page saying why. `None`, the run over and the page told, when the
/// user stopped it meanwhile or no worker can start.
async fn ready_workers(
    studio: Studio,
    workers: Vec<Rc<ModuleWorker>>,
    device: TuningDevice,
    batch_size: usize,
) -> Option<(Vec<Rc<ModuleWorker>>, TuningDevice)> {
    let TuningDevice::WebGpu = device else {
        return Some((workers, device));
    };
    let Err(why_not) = start_webgpu(&workers[0]).await else {
        return Some((workers, device));
    };
    stop_all(&workers, "WebGPU did not start for the fine-tune");
    let end = |notice: Option<String>| {
        studio.tuning.workers.set_value(Vec::new());
        studio.tuning.state.set(TuningState::Idle);
        match notice {
            Some(error) => studio.notices.error(error),
            None => studio.notices.info("Fine-tuning stopped"),
        }
    };
    if matches!(&why_not, ModuleWorkerError::Stopped { why, .. } if why == STOPPED_BY_USER) {
        end(None);
        return None;
    }
    let cpu = match cpu_workers(batch_size) {
        Ok(cpu) => cpu,
        Err(e) => {
            end(Some(format!("Cannot fine-tune: {}", with_causes(&e))));
            return None;
        }
    };
    studio.notices.info(format!(
        "WebGPU could not fine-tune ({}); fine-tuning on the CPU",
        with_causes(&why_not)
    ));
    let device = TuningDevice::Cpu { workers: cpu.len() };
    studio.tuning.workers.set_value(cpu.clone());
    studio.tuning.state.update(|state| {
        if let TuningState::Running(progress) = state {
            progress.device = device;
        }
    });
    Some((cpu, device))
}

/// Sets WebGPU up in the WebGPU fine-tuning worker (its `start`, as the page's WebGPU worker
/// is), within the time the page's WebGPU worker is given; a failure stops it.
async fn start_webgpu(worker: &ModuleWorker) -> Result<(), ModuleWorkerError> {
    let sent = worker.send("start", &Array::new(), &Array::new())?;
    let started = within(
        sent,
        START_TIMEOUT_S,
        &format!("it did not start within {START_TIMEOUT_S} s"),
    );
    worker.reply("start", started).await.map(|_| ())
}

/// Why a run stopped when the user stopped it.
const STOPPED_BY_USER: &str = "stopped by the user";

/// Stops every worker of a run for `why`.
fn stop_all(workers: &[Rc<ModuleWorker>], why: &str) {
    for worker in workers {
        worker.stop(why);
    }
}

/// Calls `call` on every worker at once, worker `i` with the arguments and the buffers to hand
/// over that `args(i)` gives, and waits for every reply, in worker order. A failed call stops
/// its worker, as [`ModuleWorker::call`] does.
async fn call_each(
    workers: &[Rc<ModuleWorker>],
    call: &'static str,
    args: impl Fn(usize) -> (Array, Array),
) -> Result<Vec<JsValue>, ModuleWorkerError> {
    let sent: Vec<_> = workers
        .iter()
        .enumerate()
        .map(|(i, worker)| {
            let (args, transfer) = args(i);
            worker.send(call, &args, &transfer)
        })
        .collect();
    let mut replies = Vec::with_capacity(workers.len());
    for (worker, sent) in workers.iter().zip(sent) {
        let reply = match sent {
            Ok(promise) => worker.reply(call, promise).await,
            Err(e) => Err(e),
        };
        if let Err(e) = &reply {
            worker.stop(&with_causes(e));
        }
        replies.push(reply?);
    }
    Ok(replies)
}

/// Runs the fine-tune in `workers` to its end (or until they are stopped), updating the page's
/// progress; the best epoch's weights are fetched as soon as it is best, so that a stopped run
/// keeps them. Each step: every worker computes its share, and every worker applies all of
/// them, relayed by the page.
async fn run(
    studio: Studio,
    workers: &[Rc<ModuleWorker>],
    start: &TuningStart<'_>,
) -> Result<TuningResult, ModuleWorkerError> {
    let TuningStart {
        weights,
        name: start_name,
        provenance: start_provenance,
        set,
        reference,
        rehearsal,
        settings,
        device,
    } = *start;
    let settings_json = serde_json::to_string(&settings).unwrap_or_else(|_| "{}".into());
    // The first worker scores the held-back pairs after each epoch; the last scores the
    // reference pairs meanwhile (with one worker, the same one).
    let scores_reference = workers.len() - 1;
    // Each worker gets its own copy of the pairs, handed over.
    let started = call_each(workers, "start_tuning", |i| {
        let images = Uint8Array::from(set.images.as_slice());
        let forces = Float32Array::from(set.forces.as_slice());
        let reference = reference.filter(|_| i == scores_reference);
        let reference_images = Uint8Array::from(reference.map_or(&[][..], |r| &r.images[..]));
        let reference_forces = Float32Array::from(reference.map_or(&[][..], |r| &r.forces[..]));
        let rehearsal_images = Uint8Array::from(rehearsal.map_or(&[][..], |r| &r.images[..]));
        let rehearsal_forces = Float32Array::from(rehearsal.map_or(&[][..], |r| &r.forces[..]));
        let (args, transfer) = (Array::new(), Array::new());
        for buffer in [&images, &reference_images, &rehearsal_images] {
            transfer.push(&buffer.buffer());
        }
        for buffer in [&forces, &reference_forces, &rehearsal_forces] {
            transfer.push(&buffer.buffer());
        }
        for value in [
            Uint8Array::from(weights).into(),
            JsValue::from_str(start_name),
            JsValue::from(WORK_SIZE.width as u32),
            JsValue::from(WORK_SIZE.height as u32),
            images.into(),
            forces.into(),
            reference_images.into(),
            reference_forces.into(),
            rehearsal_images.into(),
            rehearsal_forces.into(),
            JsValue::from_str(&settings_json),
            JsValue::from_bool(i > 0),
        ] {
            args.push(&value);
        }
        (args, transfer)
    })
    .await?;
    let before_reference: Option<HeldBackScores> = serde_json::from_value(
        json_reply(started[scores_reference].clone())["before_reference"].clone(),
    )
    .map_err(|e| reply_error("start_tuning", &e.to_string()))?;
    let started = json_reply(started.into_iter().next().unwrap_or_default());
    let split = (
        started["train"].as_u64().unwrap_or(0) as usize,
        started["held_back"].as_u64().unwrap_or(0) as usize,
    );
    let steps_per_epoch = started["steps_per_epoch"].as_u64().unwrap_or(1) as usize;
    let before: HeldBackScores = serde_json::from_value(started["before"].clone())
        .map_err(|e| reply_error("start_tuning", &e.to_string()))?;
    let total = steps_per_epoch * settings.max_epochs;
    let update = |f: &dyn Fn(&mut TuningProgress)| {
        studio.tuning.state.update(|state| {
            if let TuningState::Running(progress) = state {
                f(progress);
            }
        })
    };
    update(&|p| {
        p.split = split;
        p.steps = (0, total);
        p.steps_per_epoch = steps_per_epoch;
        p.before = Some(before);
    });
    let began = now_ms();
    let (mut epochs, mut best, mut kept) = (Vec::<EpochReport>::new(), None, None);
    let mut done = 0;
    let reason = loop {
        let replies = match step(workers).await {
            Ok(replies) => replies,
            // Stopped by the user: the best epoch so far stands.
            Err(ModuleWorkerError::Stopped { why, .. }) if why == STOPPED_BY_USER => {
                break None;
            }
            Err(e) => return Err(e),
        };
        done += 1;
        let unreadable = |e: serde_json::Error| reply_error("apply", &e.to_string());
        let mut report: Option<EpochReport> =
            serde_json::from_value(replies[0]["report"].clone()).map_err(unreadable)?;
        if let Some(report) = report.as_mut().filter(|r| r.reference.is_none()) {
            report.reference =
                serde_json::from_value(replies[scores_reference]["reference"].clone())
                    .map_err(unreadable)?;
        }
        let elapsed_s = (now_ms() - began) / 1000.0;
        let in_epoch = (done % steps_per_epoch.max(1)) * settings.batch_size.max(1);
        let trained = done / steps_per_epoch.max(1) * split.0 + in_epoch.min(split.0);
        if let Some(report) = report {
            epochs.push(report);
            if report.best {
                let provenance = kept_provenance(
                    start_provenance,
                    (start_name, device, settings.start_share),
                    set,
                    split.1,
                    &before,
                    &report,
                );
                let provenance = serde_json::to_string(&provenance).unwrap_or_default();
                let bytes = workers[0]
                    .call(
                        "best_weights",
                        &Array::of1(&provenance.into()),
                        &Array::new(),
                    )
                    .await?;
                let bytes = Uint8Array::new(&bytes).to_vec();
                if !bytes.is_empty() {
                    kept = Some(Rc::<[u8]>::from(bytes));
                    best = Some(report);
                }
            }
            if report.finished {
                break report.finished_because;
            }
        }
        let epochs_now = epochs.clone();
        update(&move |p| {
            p.steps = (done, total);
            p.epochs = epochs_now.clone();
            p.pairs_per_s = Some(trained as f64 / elapsed_s.max(1e-3));
            p.seconds_left = seconds_left(elapsed_s, done, total);
        });
    };
    Ok(TuningResult {
        split,
        before,
        before_reference,
        best,
        epochs,
        reason,
        weights: kept,
    })
}

/// One training step on `workers`: each worker's share of its gradients, then every share,
/// one after another, applied by each. Returns every worker's reply, parsed (`report` and
/// `reference`: hnet-tune's `apply`).
async fn step(workers: &[Rc<ModuleWorker>]) -> Result<Vec<serde_json::Value>, ModuleWorkerError> {
    let shares = call_each(workers, "share", |i| {
        (Array::of1(&JsValue::from(i as u32)), Array::new())
    })
    .await?;
    let shares: Vec<Float32Array> = shares.into_iter().map(JsCast::unchecked_into).collect();
    let length = shares.iter().map(Float32Array::length).sum();
    let all = Float32Array::new_with_length(length);
    let mut at = 0;
    for share in &shares {
        all.set(share, at);
        at += share.length();
    }
    let applied = call_each(workers, "apply", |_| {
        let copy = Float32Array::new(&all);
        (Array::of1(&copy), Array::of1(&copy.buffer()))
    })
    .await?;
    Ok(applied.into_iter().map(json_reply).collect())
}

/// A worker's JSON reply, parsed (`null` when it is not JSON text).
fn json_reply(reply: JsValue) -> serde_json::Value {
    reply
        .as_string()
        .and_then(|text| serde_json::from_str(&text).ok())
        .unwrap_or(serde_json::Value::Null)
}

fn reply_error(call: &'static str, what: &str) -> ModuleWorkerError {
    ModuleWorkerError::Call {
        worker: "the fine-tuning worker",
        call,
        cause: crate::browser::JsError::missing(&format!("an unreadable reply ({what})")),
    }
}
