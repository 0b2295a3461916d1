//! The page's state: signals gathered in [`Studio`], shared with the components through Leptos'
//! context, and the actions that change them (run H-Net, keep the twin's pair or a cine frame,
//! play a DICOM cine and trace its force, delete and restore pairs, undo). The labeling [`Workspace`] is saved to the browser's IndexedDB after
//! every change (see [`Studio::persist`]), so that a reload loses nothing. The components only
//! render this state and call these actions.

use std::collections::HashMap;
use std::rc::Rc;

use leptos::prelude::*;

use crate::bundled::{self, FetchError};
use crate::catheter_3d::{
    Catheter3d, FitMasks, PairGeometry, PairMasks, pair_views, reconstruct_pair,
};
use crate::catheter_calibration;
use crate::cine::CinePlayer;
use crate::compute::{self, Backend, BackendChoice};
use crate::engine::{Engine, EngineError, Prediction, WeightsOrigin};
use crate::error_text::with_causes;
use crate::gpu_worker::GpuWorker;
use crate::orbit_camera::OrbitCamera;
use crate::storage;
use crate::twin_live::{TwinControls, XrayBackground};
use crate::webgpu_check;
use crate::workspace::{LabeledPair, RemovedPair, Tool, View, Workspace};
use hnet_model::catheter_entry::EntrySetting;
use hnet_twin::carm::Biplane;
use hnet_twin::catalogue::StiffnessCalibration;
use hnet_twin::sensor_plate::ContactError;

mod cine;

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

/// A message for the user.
#[derive(Debug, Clone, PartialEq)]
pub struct Notice {
    /// Whether it reports a problem.
    pub error: bool,
    /// The text.
    pub text: String,
    /// What the notice's button undoes, if it has one.
    pub undo: Option<Undoable>,
}

/// An action the notice bar can undo.
#[derive(Debug, Clone, PartialEq)]
pub enum Undoable {
    /// A deleted pair: undo puts it back, with its masks, force label and history.
    Deletion(Box<RemovedPair>),
}

/// What the pointer does on a view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointerTool {
    /// Paints catheter.
    Brush,
    /// Erases catheter.
    Eraser,
    /// Moves the zoomed view.
    Pan,
    /// Changes the window/level of a DICOM frame's plane.
    WindowLevel,
}

impl PointerTool {
    /// The mask tool, for painting tools.
    pub fn mask_tool(self) -> Option<Tool> {
        match self {
            PointerTool::Brush => Some(Tool::Brush),
            PointerTool::Eraser => Some(Tool::Eraser),
            PointerTool::Pan | PointerTool::WindowLevel => None,
        }
    }
}

/// Zoom and pan of one view: screen = `offset + scale · image` in canvas pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewTransform {
    /// Canvas pixels per image pixel.
    pub scale: f64,
    /// Canvas position of the image's top-left corner.
    pub offset: [f64; 2],
}

/// Side of a view's canvas, canvas pixels.
pub const CANVAS_SIDE: f64 = 448.0;

impl Default for ViewTransform {
    fn default() -> Self {
        Self {
            scale: CANVAS_SIDE / crate::imaging::WORK_SIZE as f64,
            offset: [0.0, 0.0],
        }
    }
}

impl ViewTransform {
    /// Image coordinates of a canvas point.
    pub fn to_image(&self, canvas: [f64; 2]) -> [f64; 2] {
        [
            (canvas[0] - self.offset[0]) / self.scale,
            (canvas[1] - self.offset[1]) / self.scale,
        ]
    }

    /// Canvas coordinates of an image point.
    pub fn to_canvas(&self, image: [f64; 2]) -> [f64; 2] {
        [
            self.offset[0] + image[0] * self.scale,
            self.offset[1] + image[1] * self.scale,
        ]
    }

    /// Zooms by `factor` keeping the canvas point `at` fixed (between 1x and 16x the fit).
    pub fn zoomed(&self, factor: f64, at: [f64; 2]) -> Self {
        let fit = Self::default().scale;
        let scale = (self.scale * factor).clamp(fit, 16.0 * fit);
        let image = self.to_image(at);
        Self {
            scale,
            offset: [at[0] - image[0] * scale, at[1] - image[1] * scale],
        }
    }
}

/// The catheter in 3D of one pair, as the page computed it ([`Studio::reconstruct_shown`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CatheterReading {
    /// The pair's id.
    pub id: String,
    /// The masks the rod was asked to be fitted to.
    pub fit_masks: FitMasks,
    /// H-Net's force estimate of the prediction on hand when it was made, newtons (whose masks
    /// it was fitted to, when it was fitted to H-Net's).
    pub prediction_force_n: Option<[f32; 3]>,
    /// Its views (for drawing the C-arms).
    pub views: Biplane,
    /// The catheter and its physics force, or why there is none (with its causes).
    pub result: Result<Catheter3d, String>,
    /// Time of the centrelines, the reconstruction and the rod fit, milliseconds.
    pub millis: f64,
}

impl CatheterReading {
    /// The physics estimate to combine with H-Net's estimate `hnet_n`
    /// ([`Catheter3d::for_combination`]), when the rod was fitted to the masks of the prediction
    /// that gave `hnet_n` (not to an earlier prediction's, of other weights).
    pub fn physics_for(&self, hnet_n: [f32; 3]) -> Option<([f32; 3], Option<[f32; 3]>)> {
        if self.prediction_force_n != Some(hnet_n) {
            return None;
        }
        self.result.as_ref().ok()?.for_combination()
    }
}

/// Which source panel is open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceTab {
    /// Two image files.
    Images,
    /// A biplane DICOM cine.
    Cine,
    /// The live twin's sliders.
    Twin,
    /// The synthetic X-ray background composer.
    Background,
}

/// Everything the page's components share.
#[derive(Clone, Copy)]
pub struct Studio {
    /// The network.
    pub model: RwSignal<ModelState, LocalStorage>,
    /// Which backend the user asked for.
    pub backend_choice: RwSignal<BackendChoice>,
    /// Through which edge the catheter enters the views H-Net reads (as trained: the bottom).
    pub catheter_entry: RwSignal<EntrySetting>,
    /// The labeled pairs.
    pub workspace: RwSignal<Workspace>,
    /// The live twin's pair, shown until kept or another pair is selected.
    pub draft: RwSignal<Option<LabeledPair>>,
    /// H-Net's latest prediction per pair id.
    pub predictions: RwSignal<HashMap<String, Prediction>>,
    /// What the page is busy with, if anything.
    pub busy: RwSignal<Option<String>>,
    /// The latest message.
    pub notice: RwSignal<Option<Notice>>,
    /// Show H-Net's masks.
    pub show_prediction: RwSignal<bool>,
    /// Show the label masks.
    pub show_label: RwSignal<bool>,
    /// Opacity of the mask overlays, 0-1.
    pub opacity: RwSignal<f64>,
    /// What the pointer does.
    pub tool: RwSignal<PointerTool>,
    /// Brush radius, image pixels.
    pub brush_radius: RwSignal<f64>,
    /// Zoom and pan of view A and view B.
    pub transforms: [RwSignal<ViewTransform>; 2],
    /// The twin's sliders.
    pub twin: RwSignal<TwinControls>,
    /// The catheter's stiffness calibrated from the pairs' measured force labels, for this
    /// session ([`crate::catheter_calibration`]); `None`: the stiffness the page assumes.
    pub calibration: RwSignal<Option<StiffnessCalibration>>,
    /// The synthetic X-ray background.
    pub background: RwSignal<XrayBackground>,
    /// The open source panel.
    pub tab: RwSignal<SourceTab>,
    /// Counter of live twin renders (the draft's id).
    pub draft_serial: RwSignal<u64>,
    /// H-Net was asked to run while it was busy: run again on the pair on screen when done.
    pub rerun: RwSignal<bool>,
    /// The catheter in 3D and its physics force, for the pair on screen.
    pub catheter: RwSignal<Option<CatheterReading>>,
    /// Which masks the rod is fitted to.
    pub fit_masks: RwSignal<FitMasks>,
    /// The pointer on a view (image pixels), whose epipolar line the other view draws.
    pub epipolar_pointer: RwSignal<Option<(View, [f64; 2])>>,
    /// The 3D view's camera (its target and framing follow the catheter).
    pub orbit: RwSignal<OrbitCamera>,
    /// The DICOM cine, once loaded. Read it with `with`: it holds every frame.
    pub cine: RwSignal<Option<CinePlayer>>,
    /// Counts loaded cines, so that a trace of an earlier one stops.
    pub cine_serial: RwSignal<u64>,
    /// Whether the cine plays.
    pub playing: RwSignal<bool>,
    /// The cine's playback timer, while it plays.
    playback: StoredValue<Option<IntervalHandle>>,
    /// Frames traced and frames to trace, while H-Net runs over the cine.
    pub trace_progress: RwSignal<Option<(usize, usize)>>,
    /// The user asked to stop the trace.
    pub trace_cancelled: RwSignal<bool>,
}

impl Default for Studio {
    fn default() -> Self {
        Self::new()
    }
}

impl Studio {
    /// The state of a page that has just opened: no model yet, no pairs.
    pub fn new() -> Self {
        Self {
            model: RwSignal::new_local(ModelState::Loading("Loading H-Net…".into())),
            backend_choice: RwSignal::new(BackendChoice::Auto),
            catheter_entry: RwSignal::new(EntrySetting::AS_TRAINED),
            workspace: RwSignal::new(Workspace::default()),
            draft: RwSignal::new(None),
            predictions: RwSignal::new(HashMap::new()),
            busy: RwSignal::new(None),
            notice: RwSignal::new(None),
            show_prediction: RwSignal::new(true),
            show_label: RwSignal::new(true),
            opacity: RwSignal::new(0.5),
            tool: RwSignal::new(PointerTool::Brush),
            brush_radius: RwSignal::new(3.0),
            transforms: [
                RwSignal::new(ViewTransform::default()),
                RwSignal::new(ViewTransform::default()),
            ],
            twin: RwSignal::new(TwinControls::default()),
            calibration: RwSignal::new(None),
            background: RwSignal::new(XrayBackground::phantom()),
            tab: RwSignal::new(SourceTab::Images),
            draft_serial: RwSignal::new(0),
            rerun: RwSignal::new(false),
            catheter: RwSignal::new(None),
            fit_masks: RwSignal::new(FitMasks::default()),
            epipolar_pointer: RwSignal::new(None),
            orbit: RwSignal::new(OrbitCamera::default()),
            cine: RwSignal::new(None),
            cine_serial: RwSignal::new(0),
            playing: RwSignal::new(false),
            playback: StoredValue::new(None),
            trace_progress: RwSignal::new(None),
            trace_cancelled: RwSignal::new(false),
        }
    }

    /// Reports a problem to the user.
    pub fn error(&self, text: impl Into<String>) {
        self.notice.set(Some(Notice {
            error: true,
            text: text.into(),
            undo: None,
        }));
    }

    /// Tells the user something.
    pub fn info(&self, text: impl Into<String>) {
        self.notice.set(Some(Notice {
            error: false,
            text: text.into(),
            undo: None,
        }));
    }

    /// Deletes the pair on screen, from the page and the browser's storage; the notice offers
    /// to undo it.
    pub fn delete_current_pair(&self) {
        let mut removed = None;
        self.draft.set(None);
        self.workspace.update(|ws| removed = ws.remove_current());
        let Some(removed) = removed else { return };
        let id = removed.pair.id.clone();
        self.predictions.update(|p| {
            p.remove(&id);
        });
        let studio = *self;
        leptos::task::spawn_local(async move {
            match storage::delete_pair(&id).await {
                Ok(()) => studio.notice.set(Some(Notice {
                    error: false,
                    text: format!("{id} deleted"),
                    undo: Some(Undoable::Deletion(Box::new(removed))),
                })),
                Err(e) => studio.error(format!(
                    "{id}: not deleted from the browser: {}",
                    with_causes(&e)
                )),
            }
        });
        self.run_model();
    }

    /// Undoes what the notice offers to undo.
    pub fn undo_notice(&self, undo: Undoable) {
        match undo {
            Undoable::Deletion(removed) => {
                let id = removed.pair.id.clone();
                let mut restored = None;
                self.draft.set(None);
                self.workspace.update(|ws| restored = ws.restore(*removed));
                match restored {
                    Some(id) => {
                        self.persist(Some(id.clone()));
                        self.info(format!("{id} restored"));
                        self.run_model();
                    }
                    None => self.error(format!(
                        "{id} cannot be restored: a pair with that id was added since"
                    )),
                }
            }
        }
    }

    /// Calls `f` with the pair on screen: the live twin's draft, else the workspace's current
    /// pair. Tracks both.
    pub fn with_shown<R>(&self, f: impl FnOnce(Option<&LabeledPair>) -> R) -> R {
        self.draft.with(|draft| match draft {
            Some(pair) => f(Some(pair)),
            None => self.workspace.with(|ws| f(ws.current())),
        })
    }

    /// Id of the pair on screen.
    pub fn shown_id(&self) -> Option<String> {
        self.with_shown(|p| p.map(|p| p.id.clone()))
    }

    /// Whether the pair on screen is the unsaved twin draft.
    pub fn showing_draft(&self) -> bool {
        self.draft.with(Option::is_some)
    }

    /// Whether the pair on screen is an unsaved frame of the DICOM cine.
    pub fn showing_cine_frame(&self) -> bool {
        self.draft.with(|d| {
            d.as_ref()
                .is_some_and(|p| matches!(p.source, crate::workspace::PairSource::Dicom { .. }))
        })
    }

    /// Saves pair `id` of the workspace to the browser's storage.
    pub fn persist(&self, id: Option<String>) {
        let Some(id) = id else { return };
        let Some(pair) = self.workspace.with_untracked(|ws| ws.pair(&id).cloned()) else {
            return;
        };
        let studio = *self;
        leptos::task::spawn_local(async move {
            if let Err(e) = storage::save_pair(&pair).await {
                studio.error(format!(
                    "{}: not saved in the browser: {}",
                    pair.id,
                    with_causes(&e)
                ));
            }
        });
    }

    /// Saves what changed in pairs whose images and masks did not (splits, force labels)
    /// without encoding their images again; a pair the browser never stored is saved whole.
    pub fn persist_metadata(&self, ids: &[String]) {
        let metadata = self.workspace.with_untracked(|ws| {
            ids.iter()
                .filter_map(|id| ws.pair(id))
                .map(storage::PairMetadata::of)
                .collect::<Result<Vec<_>, _>>()
        });
        let studio = *self;
        let count = ids.len();
        leptos::task::spawn_local(async move {
            let saved = match metadata {
                Ok(metadata) => storage::save_metadata(metadata).await,
                Err(e) => Err(e),
            };
            match saved {
                Ok(unsaved) => {
                    for id in unsaved {
                        studio.persist(Some(id));
                    }
                }
                Err(e) => studio.error(format!(
                    "{count} pair(s): changes not saved in the browser: {}",
                    with_causes(&e)
                )),
            }
        });
    }

    /// Adds a pair to the workspace, shows it, saves it and runs H-Net on it.
    pub fn add_pair(&self, pair: LabeledPair) {
        let id = pair.id.clone();
        self.draft.set(None);
        self.workspace.update(|ws| ws.add(pair));
        self.persist(Some(id));
        self.run_model();
    }

    /// Keeps the live twin's draft as a workspace pair.
    pub fn keep_draft(&self) {
        let Some(mut pair) = self.draft.get_untracked() else {
            return;
        };
        let draft_id = pair.id.clone();
        pair.id = self.workspace.with_untracked(Workspace::next_id);
        let id = pair.id.clone();
        self.predictions.update(|p| {
            if let Some(prediction) = p.remove(&draft_id) {
                p.insert(id.clone(), prediction);
            }
        });
        self.draft.set(None);
        self.workspace.update(|ws| ws.add(pair));
        self.persist(Some(id.clone()));
        self.info(format!("{id} added to the labeled pairs"));
    }

    /// Runs H-Net on the pair on screen when the model is ready. A request made while H-Net is
    /// busy runs once the current inference is done, on the pair then on screen.
    pub fn run_model(&self) {
        let ModelState::Ready(engine) = self.model.get_untracked() else {
            return;
        };
        if self.busy.get_untracked().is_some() {
            self.rerun.set(true);
            return;
        }
        let shown = self
            .draft
            .with_untracked(|d| d.clone())
            .or_else(|| self.workspace.with_untracked(|ws| ws.current().cloned()));
        let Some(pair) = shown else {
            return;
        };
        let studio = *self;
        let id = pair.id;
        let entry = self.catheter_entry.get_untracked();
        self.busy.set(Some(format!("Running H-Net on {id}…")));
        leptos::task::spawn_local(async move {
            match engine.infer(&pair.view_a, &pair.view_b, entry).await {
                // A reading under a model or an entry setting the page has left since is not
                // shown: the rerun below reads the pair again.
                Ok(prediction)
                    if studio.uses(&engine) && studio.catheter_entry.get_untracked() == entry =>
                {
                    studio.predictions.update(|p| {
                        p.insert(id, prediction);
                    })
                }
                Ok(_) => {}
                Err(e) => {
                    studio.error(format!("H-Net failed on {id}: {}", with_causes(&e)));
                    studio.leave_webgpu_after(&engine, &e);
                }
            }
            studio.busy.set(None);
            if studio.rerun.get_untracked() {
                studio.rerun.set(false);
                let current = studio.shown_id_untracked();
                if current
                    .is_some_and(|id| studio.predictions.with_untracked(|p| !p.contains_key(&id)))
                {
                    studio.run_model();
                }
            }
        });
    }

    /// Whether `engine` is the model the page runs now (not one it has since replaced).
    fn uses(&self, engine: &Rc<Engine>) -> bool {
        matches!(
            self.model.get_untracked(),
            ModelState::Ready(current) if Rc::ptr_eq(&current, engine)
        )
    }

    /// After `engine` failed on WebGPU with `error`, the same weights on the CPU, which says why
    /// (the worker is stopped: every later call would fail too), and the pair on screen again.
    /// Any other failure, or an engine the page no longer uses, changes nothing.
    fn leave_webgpu_after(&self, engine: &Rc<Engine>, error: &EngineError) {
        if !self.uses(engine) || !matches!(error, EngineError::WebGpu(_)) {
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
                self.model.set(ModelState::Ready(Rc::new(cpu)));
                self.run_model();
            }
            Err(e) => self.model.set(ModelState::Failed(with_causes(&e))),
        }
    }

    /// Id of the pair on screen, without tracking.
    fn shown_id_untracked(&self) -> Option<String> {
        self.draft
            .with_untracked(|d| d.as_ref().map(|p| p.id.clone()))
            .or_else(|| {
                self.workspace
                    .with_untracked(|ws| ws.current().map(|p| p.id.clone()))
            })
    }

    /// Renders the live twin with the current sliders and background as the draft.
    pub fn render_twin(&self) {
        let controls = self.twin.get_untracked();
        let serial = self.draft_serial.get_untracked() + 1;
        self.draft_serial.set(serial);
        let id = format!("twin-{serial}");
        let result = self.background.with_untracked(|bg| controls.render(id, bg));
        match result {
            Ok(pair) => self.replace_draft(Some(pair)),
            Err(ContactError::BeyondSensorRange {
                force_n,
                max_force_n,
            }) => self.error(format!(
                "this press gives {force_n:.2} N, beyond the bench sensor's {max_force_n} N \
                 range: press less or tilt the plate less"
            )),
            Err(e) => self.error(format!(
                "the catheter does not settle under this load ({}); try a smaller force or a \
                 stiffer catheter",
                with_causes(&e)
            )),
        }
    }

    /// Shows `pair` as the unsaved draft (or none), forgetting the previous draft's prediction.
    fn replace_draft(&self, pair: Option<LabeledPair>) {
        if let Some(old) = self
            .draft
            .with_untracked(|d| d.as_ref().map(|p| p.id.clone()))
        {
            self.predictions.update(|p| {
                p.remove(&old);
            });
        }
        self.draft.set(pair);
    }

    /// Applies a workspace change that returns the changed pair's id, and saves that pair.
    pub fn edit(&self, change: impl FnOnce(&mut Workspace) -> Option<String>) {
        let mut changed = None;
        self.workspace.update(|ws| changed = change(ws));
        self.persist(changed);
    }

    /// The id of the pair on screen for labeling: the twin's draft is kept first (labels are
    /// only given to kept pairs).
    pub fn labeled_pair_id(&self) -> Option<String> {
        if self.showing_draft() {
            self.keep_draft();
        }
        self.workspace
            .with_untracked(|ws| ws.current().map(|p| p.id.clone()))
    }

    /// Uses H-Net's masks of the pair on screen as its label masks (one undo step).
    pub fn accept_predicted_masks(&self) {
        let Some(id) = self.labeled_pair_id() else {
            return;
        };
        let Some(prediction) = self.predictions.with_untracked(|p| p.get(&id).cloned()) else {
            self.error("run H-Net first: there are no predicted masks for this pair");
            return;
        };
        let masks = [
            crate::imaging::binarize(&prediction.mask_a),
            crate::imaging::binarize(&prediction.mask_b),
        ];
        self.edit(|ws| ws.set_masks(masks));
        self.show_label.set(true);
    }

    /// Fits both views in their canvases (no zoom, no pan).
    pub fn fit_views(&self) {
        for t in self.transforms {
            t.set(ViewTransform::default());
        }
    }

    /// Reconstructs the catheter of the pair on screen in 3D and fits the rod to it (the label
    /// masks, else H-Net's, or H-Net's as [`Studio::fit_masks`] asks), into
    /// [`Studio::catheter`]. A failure is kept there as its message; nothing else changes.
    pub fn reconstruct_shown(&self) {
        let shown = self
            .draft
            .with_untracked(|d| d.clone())
            .or_else(|| self.workspace.with_untracked(|ws| ws.current().cloned()));
        let Some(pair) = shown else {
            self.catheter.set(None);
            return;
        };
        let prediction = self.predictions.with_untracked(|p| {
            p.get(&pair.id)
                .map(|p| (p.mask_a.clone(), p.mask_b.clone(), p.force_n))
        });
        let controls = self.twin.get_untracked();
        let calibration = self.calibration.get_untracked();
        let choice = self.fit_masks.get_untracked();
        let clock = web_sys::window().and_then(|w| w.performance());
        let now = || clock.as_ref().map_or(0.0, |p| p.now());
        let start = now();
        let result =
            PairGeometry::of(&pair, &controls, calibration.as_ref()).and_then(|geometry| {
                let predicted = prediction.as_ref().map(|(a, b, _)| [&a[..], &b[..]]);
                reconstruct_pair(&geometry, &PairMasks::of(&pair, predicted, choice)?)
            });
        let millis = now() - start;
        self.catheter.set(Some(CatheterReading {
            views: pair_views(&pair),
            id: pair.id,
            fit_masks: choice,
            prediction_force_n: prediction.and_then(|(_, _, force)| force),
            result: result.map_err(|e| with_causes(&e)),
            millis,
        }));
    }

    /// Calibrates the catheter's stiffness from the pairs' measured force labels
    /// ([`crate::catheter_calibration`]); the 3D step and the trace then read every pair with
    /// it. A refusal says why and keeps the previous calibration.
    pub fn calibrate_catheter(&self) {
        let controls = self.twin.get_untracked();
        let outcome = self.workspace.with_untracked(|ws| {
            self.predictions.with_untracked(|predictions| {
                let predicted = |id: &str| {
                    predictions
                        .get(id)
                        .map(|p| [p.mask_a.clone(), p.mask_b.clone()])
                };
                catheter_calibration::calibrate_catheter(&ws.pairs, &predicted, &controls)
            })
        });
        match outcome {
            Ok(outcome) => {
                let mut text = format!(
                    "catheter calibrated: {}",
                    catheter_calibration::describe(&outcome.calibration)
                );
                if !outcome.left_out.is_empty() {
                    text = format!("{text}; left out: {}", outcome.left_out.join("; "));
                }
                self.calibration.set(Some(outcome.calibration));
                self.info(text);
            }
            Err(e) => self.error(with_causes(&e)),
        }
    }

    /// Undo (`redo` false) or redo the last mask edit.
    pub fn undo_redo(&self, redo: bool) {
        self.draft.set(None);
        self.edit(|ws| if redo { ws.redo() } else { ws.undo() });
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
    let backend = compute::choose_backend(studio.backend_choice.get_untracked()).await;
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
            force_n: p.head_force_n.unwrap_or([f32::NAN; 3]),
        }
    }
    let scale = web_sys::window()
        .and_then(|w| w.location().search().ok())
        .map_or(1.0, |query| webgpu_check::tolerance_scale(&query));
    let difference = webgpu_check::Difference::between(output(&expected), output(&found));
    if !difference.within(scale) {
        return Err(difference.refusal(scale));
    }
    Ok(gpu.with_check(difference.text()))
}

/// Loads the model (bundled weights, or `weights`) on the chosen backend. On failure the model
/// that was loaded stays.
pub fn load_model(studio: Studio, weights: Option<(Rc<[u8]>, String, WeightsOrigin)>) {
    let previous = studio.model.get_untracked();
    let name = weights.as_ref().map(|w| w.1.clone());
    studio.model.set(ModelState::Loading(match &name {
        Some(name) => format!("Loading {name}…"),
        None => "Loading H-Net…".into(),
    }));
    leptos::task::spawn_local(async move {
        match load_engine(studio, weights).await {
            Ok(engine) => {
                let engine = Rc::new(engine);
                studio.model.set(ModelState::Ready(engine.clone()));
                if name.is_some() {
                    studio.info(format!("Loaded {}", engine.weights_name));
                }
                studio.predictions.set(HashMap::new());
                studio.run_model();
            }
            Err(e) => {
                let text = with_causes(&e);
                match previous {
                    ModelState::Ready(engine) => {
                        studio.model.set(ModelState::Ready(engine.clone()));
                        studio.error(format!("{text}. Still using {}.", engine.weights_name));
                    }
                    _ => studio.model.set(ModelState::Failed(text)),
                }
            }
        }
    });
}

/// Keeps [`Studio::catheter`] up to date: after the pair on screen, its masks, H-Net's masks,
/// the masks the rod is to be fitted to or the twin's catheter settings change (not during a
/// brush stroke), the catheter is reconstructed again, once the changes have paused for a
/// moment (a slider being dragged renders many pairs).
pub fn install_reconstruction(studio: Studio) {
    let serial = StoredValue::new(0u64);
    Effect::new(move |_| {
        let shown = studio.shown_id();
        studio.predictions.track();
        studio.twin.track();
        studio.calibration.track();
        studio.fit_masks.track();
        if studio.workspace.with(Workspace::is_stroking) {
            return;
        }
        if shown.is_none() {
            studio.catheter.set(None);
            return;
        }
        serial.update_value(|s| *s += 1);
        let mine = serial.get_value();
        set_timeout(
            move || {
                if serial.get_value() == mine {
                    studio.reconstruct_shown();
                }
            },
            std::time::Duration::from_millis(40),
        );
    });
}

/// Ids of both views, for element ids and labels.
pub fn view_index(view: View) -> usize {
    match view {
        View::A => 0,
        View::B => 1,
    }
}
