//! The network on the page's state: loading the weights on the backend the user chose (WebGPU
//! checked against the CPU before it is trusted), and running it on the pair on screen.

use std::collections::HashMap;
use std::rc::Rc;

use leptos::prelude::*;

use super::{PairStore, Studio};
use crate::browser::sleep_ms;
use crate::bundled::{self, FetchError};
use crate::compute::BackendChoice;
use crate::compute::{self, Backend};
use crate::cpu_pool::WorkersStatus;
use crate::engine::{Engine, EngineError, Prediction, WeightsOrigin};
use crate::error_text::with_causes;
use crate::gpu_worker::GpuWorker;
use crate::{page_query, webgpu_check};
use hnet_model::catheter_entry::EntrySetting;
use hnet_units::TipForce;

/// The model's state.
#[derive(Clone)]
pub enum ModelState {
    /// Choosing the backend and loading the weights.
    Loading(String),
    /// Ready to run.
    Ready(Rc<Engine>),
    /// No model could be loaded.
    Failed(String),
}

/// The network's state: its engine, its CPU workers, the user's choices of backend and catheter
/// entry, and its predictions.
#[derive(Clone, Copy)]
pub struct NetworkStore {
    /// The network.
    pub model: RwSignal<ModelState, LocalStorage>,
    /// The CPU workers that read the views, as the model bar shows them.
    pub cpu_workers: RwSignal<WorkersStatus>,
    /// Which backend the user asked for.
    pub backend_choice: RwSignal<BackendChoice>,
    /// Through which edge the catheter enters the views H-Net reads (as trained: the bottom).
    pub catheter_entry: RwSignal<EntrySetting>,
    /// H-Net's latest prediction per pair id.
    pub predictions: RwSignal<HashMap<String, Prediction>>,
    /// H-Net was asked to run while it was busy: run again on the pair on screen when done.
    pub rerun: RwSignal<bool>,
}

impl NetworkStore {
    /// No network yet (loading), automatic backend, catheters read as trained.
    pub fn new() -> Self {
        Self {
            model: RwSignal::new_local(ModelState::Loading("Loading H-Net…".into())),
            cpu_workers: RwSignal::new(WorkersStatus::NotUsed),
            backend_choice: RwSignal::new(BackendChoice::Auto),
            catheter_entry: RwSignal::new(EntrySetting::AS_TRAINED),
            predictions: RwSignal::new(HashMap::new()),
            rerun: RwSignal::new(false),
        }
    }

    /// H-Net's prediction of the pair `pairs` shows, once made: the one memo of it. It follows
    /// the shown pair's id, not the pair itself, so that a brush stroke does not copy it.
    pub fn shown_prediction(&self, pairs: PairStore) -> Memo<Option<Prediction>> {
        let predictions = self.predictions;
        let shown_id = Memo::new(move |_| pairs.shown_id());
        Memo::new(move |_| {
            let id = shown_id.get()?;
            predictions.with(|p| p.get(&id).cloned())
        })
    }

    /// Whether `engine` is the model the page runs now (not one it has since replaced).
    pub fn uses(&self, engine: &Rc<Engine>) -> bool {
        matches!(
            self.model.get_untracked(),
            ModelState::Ready(current) if Rc::ptr_eq(&current, engine)
        )
    }
}

impl Default for NetworkStore {
    fn default() -> Self {
        Self::new()
    }
}

impl Studio {
    /// Runs H-Net on the pair on screen when the model is ready. A request made while H-Net is
    /// busy runs once the current inference is done, on the pair then on screen.
    pub fn run_model(&self) {
        let ModelState::Ready(engine) = self.network.model.get_untracked() else {
            return;
        };
        if self.notices.busy.get_untracked().is_some() {
            self.network.rerun.set(true);
            return;
        }
        let Some(pair) = self.pairs.shown_untracked() else {
            self.start_workers(&engine);
            return;
        };
        let studio = *self;
        let id = pair.id;
        let entry = self.network.catheter_entry.get_untracked();
        self.notices
            .busy
            .set(Some(format!("Running H-Net on {id}…")));
        leptos::task::spawn_local(async move {
            match engine.infer(&pair.view_a, &pair.view_b, entry).await {
                // A reading under a model or an entry setting the page has left since is not
                // shown: the rerun below reads the pair again.
                Ok(prediction)
                    if studio.network.uses(&engine)
                        && studio.network.catheter_entry.get_untracked() == entry =>
                {
                    studio.network.predictions.update(|p| {
                        p.insert(id, prediction);
                    })
                }
                Ok(_) => {}
                Err(e) => {
                    studio
                        .notices
                        .error(format!("H-Net failed on {id}: {}", with_causes(&e)));
                    studio.leave_webgpu_after(&engine, &e);
                }
            }
            studio.notices.busy.set(None);
            // The workers start once the first estimate is on screen, so that their start
            // never delays it.
            studio.start_workers(&engine);
            if studio.network.rerun.get_untracked() {
                studio.network.rerun.set(false);
                let current = studio.pairs.shown_id_untracked();
                if current.is_some_and(|id| {
                    studio
                        .network
                        .predictions
                        .with_untracked(|p| !p.contains_key(&id))
                }) {
                    studio.run_model();
                }
            }
        });
    }

    /// Starts `engine`'s CPU workers (once) when it is the model the page runs, their state
    /// shown in the model bar.
    fn start_workers(&self, engine: &Rc<Engine>) {
        if !self.network.uses(engine) {
            return;
        }
        let studio = *self;
        let this = Rc::downgrade(engine);
        engine.start_workers(move |status| {
            // A pool of weights the page has left says nothing about the page's.
            if this
                .upgrade()
                .is_some_and(|engine| studio.network.uses(&engine))
            {
                studio.network.cpu_workers.set(status);
            }
        });
    }

    /// After `engine` failed on WebGPU with `error`, the same weights on the CPU, which says why
    /// (the worker is stopped: every later call would fail too), and the pair on screen again.
    /// Any other failure, or an engine the page no longer uses, changes nothing.
    pub(super) fn leave_webgpu_after(&self, engine: &Rc<Engine>, error: &EngineError) {
        if !self.network.uses(engine) || !matches!(error, EngineError::WebGpu(_)) {
            return;
        }
        let reason = format!("WebGPU failed ({}), so the CPU is used", with_causes(error));
        match Engine::from_weights(
            engine.weights.clone(),
            &engine.weights_name,
            engine.origin.clone(),
            reason,
        ) {
            Ok(cpu) => {
                self.network.cpu_workers.set(WorkersStatus::NotUsed);
                self.network.model.set(ModelState::Ready(Rc::new(cpu)));
                self.run_model();
            }
            Err(e) => self.network.model.set(ModelState::Failed(with_causes(&e))),
        }
    }
}

/// Why no model could be loaded.
#[derive(Debug, thiserror::Error)]
enum LoadError {
    /// The bundled weights could not be fetched.
    #[error(transparent)]
    Fetch(#[from] FetchError),
    /// The weights give no network the page can run.
    #[error(transparent)]
    Engine(#[from] EngineError),
}

/// The engine of `weights` (else the bundled weights, else an untrained H-Net) on the backend
/// the user chose. The weights are always read on the CPU first: that engine names a bad file,
/// checks WebGPU's result, and is used whenever WebGPU cannot be.
async fn load_engine(
    studio: Studio,
    weights: Option<(Rc<[u8]>, String, WeightsOrigin)>,
) -> Result<Engine, LoadError> {
    let backend = compute::choose_backend(studio.network.backend_choice.get_untracked()).await;
    let weights = match weights {
        Some(w) => Some(w),
        None => bundled::fetch_bytes(bundled::BUNDLED_WEIGHTS)
            .await?
            .map(|bytes| {
                (
                    Rc::<[u8]>::from(bytes),
                    bundled::BUNDLED_WEIGHTS.to_string(),
                    WeightsOrigin::Bundled,
                )
            }),
    };
    let reason = backend.reason().unwrap_or_default().to_string();
    let cpu = match weights {
        Some((bytes, name, origin)) => Engine::from_weights(bytes, &name, origin, reason)?,
        None => Engine::untrained(reason)?,
    };
    Ok(match backend {
        Backend::WebGpu => onto_webgpu(cpu).await,
        Backend::Cpu { .. } => cpu,
    })
}

/// `cpu`'s network on WebGPU, once its result on the check pair ([`webgpu_check`]) is within
/// the tolerances of the CPU's; with what the check found. When the worker cannot be started,
/// fails, or differs beyond them, `cpu` itself, whose reason says why.
async fn onto_webgpu(cpu: Engine) -> Engine {
    match checked_on_webgpu(&cpu).await {
        Ok(gpu) => gpu,
        Err(reason) => cpu.with_cpu_reason(reason),
    }
}

/// [`onto_webgpu`]'s engine on WebGPU, or why the CPU is to be used.
async fn checked_on_webgpu(cpu: &Engine) -> Result<Engine, String> {
    const CPU_USED: &str = "so the CPU is used";
    /// What happened (`error`, with its causes), and so what.
    fn reason(what: &str, error: &dyn std::error::Error, so: &str) -> String {
        format!("{what} ({}), {so}", with_causes(error))
    }
    let worker = GpuWorker::shared()
        .await
        .map_err(|e| reason("WebGPU could not be set up", &e, CPU_USED))?;
    let gpu = cpu
        .on_webgpu(&worker)
        .await
        .map_err(|e| reason("WebGPU could not load the network", &e, CPU_USED))?;
    let pair = match webgpu_check::check_pair() {
        Ok(pair) => pair,
        Err(e) => {
            return Ok(gpu.with_check(format!(
                "not checked against the CPU: the check pair could not be made ({})",
                with_causes(&e)
            )));
        }
    };
    let expected = cpu
        .infer(&pair.view_a, &pair.view_b, EntrySetting::AS_TRAINED)
        .await
        .map_err(|e| {
            reason(
                "the CPU failed on the check pair",
                &e,
                "so WebGPU's result cannot be checked",
            )
        })?;
    let found = gpu
        .infer(&pair.view_a, &pair.view_b, EntrySetting::AS_TRAINED)
        .await
        .map_err(|e| reason("WebGPU failed on a check pair", &e, CPU_USED))?;
    fn output(p: &Prediction) -> webgpu_check::Output<'_> {
        webgpu_check::Output {
            masks: [&p.mask_a[..], &p.mask_b[..]],
            // Read as trained, a pair always has the force head's estimate (catheter or not);
            // a missing one reads as NaN, which the check refuses.
            force_n: p
                .head_force_n
                .unwrap_or(TipForce::new(f32::NAN, f32::NAN, f32::NAN)),
        }
    }
    let scale = page_query::webgpu_tolerance_scale(&crate::browser::page_query());
    let difference = webgpu_check::Difference::between(output(&expected), output(&found));
    if !difference.within(scale) {
        return Err(difference.refusal(scale));
    }
    Ok(gpu.with_check(difference.text()))
}

/// Loads the model (bundled weights, or `weights`) on the chosen backend. On failure the model
/// that was loaded stays.
pub fn load_model(studio: Studio, weights: Option<(Rc<[u8]>, String, WeightsOrigin)>) {
    let previous = studio.network.model.get_untracked();
    let name = weights.as_ref().map(|w| w.1.clone());
    studio.network.model.set(ModelState::Loading(match &name {
        Some(name) => format!("Loading {name}…"),
        None => "Loading H-Net…".into(),
    }));
    leptos::task::spawn_local(async move {
        match load_engine(studio, weights).await {
            Ok(engine) => {
                let engine = Rc::new(engine);
                let had_workers = matches!(
                    studio.network.cpu_workers.get_untracked(),
                    WorkersStatus::Running { .. }
                );
                studio.network.cpu_workers.set(WorkersStatus::NotUsed);
                studio.network.model.set(ModelState::Ready(engine.clone()));
                if name.is_some() {
                    studio
                        .notices
                        .info(format!("Loaded {}", engine.weights_name));
                }
                studio.network.predictions.set(HashMap::new());
                if had_workers {
                    // Mid-session (weights chosen or kept) the page already read on workers:
                    // the new weights' first estimate waits for their own workers instead of
                    // holding the page's thread for a whole pass (about 0.25 s at 224 px). When
                    // the page opens, its thread reads first, so that the workers' start never
                    // delays the first estimate.
                    studio.start_workers(&engine);
                    while studio.network.uses(&engine)
                        && matches!(
                            studio.network.cpu_workers.get_untracked(),
                            WorkersStatus::Starting(_)
                        )
                    {
                        sleep_ms(50).await;
                    }
                }
                studio.run_model();
            }
            Err(e) => {
                let text = with_causes(&e);
                match previous {
                    ModelState::Ready(engine) => {
                        studio.network.model.set(ModelState::Ready(engine.clone()));
                        studio
                            .notices
                            .error(format!("{text}. Still using {}.", engine.weights_name));
                    }
                    _ => studio.network.model.set(ModelState::Failed(text)),
                }
            }
        }
    });
}
