//! The page's state: signals gathered in [`Studio`], shared with the components through Leptos'
//! context, and the actions that change them (run H-Net, keep the twin's pair or a cine frame,
//! play a DICOM cine and trace its force, delete and restore pairs, undo). The labeling [`Workspace`] is saved to the browser's IndexedDB after
//! every change (see [`Studio::persist`]), so that a reload loses nothing. The components only
//! render this state and call these actions.

use std::collections::HashMap;
use std::rc::Rc;

use leptos::prelude::*;

use crate::catheter_3d::FitMasks;
use crate::cine::CinePlayer;
use crate::compute::BackendChoice;
use crate::cpu_pool::WorkersStatus;
use crate::engine::Prediction;
use crate::error_text::with_causes;
use crate::module_worker::ModuleWorker;
use crate::orbit_camera::OrbitCamera;
use crate::storage::{self, KeptWeights};
use crate::twin_live::{TwinControls, XrayBackground};
use crate::workspace::{LabeledPair, RemovedPair, Tool, View, Workspace};
use hnet_model::catheter_entry::EntrySetting;
use hnet_twin::reconstruction::catalogue::StiffnessCalibration;
use hnet_twin::simulator::sensor_plate::ContactError;

mod catheter;
mod cine;
mod model;
mod tuning;

pub use catheter::{CatheterReading, install_reconstruction};
pub use model::{ModelState, load_model};
pub use tuning::{KEPT_NAME, TuningProgress, TuningResult, TuningState};

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
    /// The CPU workers that read the views, as the model bar shows them.
    pub cpu_workers: RwSignal<WorkersStatus>,
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
    /// Whether a window/level drag changes both cine planes (else the dragged view's only).
    pub link_windows: RwSignal<bool>,
    /// The fine-tune running or ended ([`tuning`]).
    pub tuning: RwSignal<TuningState, LocalStorage>,
    /// Its worker, while it runs.
    tuning_worker: StoredValue<Option<Rc<ModuleWorker>>, LocalStorage>,
    /// The fine-tuned weights kept in the browser, if any.
    pub kept: RwSignal<Option<Rc<KeptWeights>>, LocalStorage>,
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
            cpu_workers: RwSignal::new(WorkersStatus::NotUsed),
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
            link_windows: RwSignal::new(false),
            tuning: RwSignal::new_local(TuningState::Idle),
            tuning_worker: StoredValue::new_local(None),
            kept: RwSignal::new_local(None),
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

    /// Whether the pair on screen is an upload not kept yet.
    pub fn showing_upload_draft(&self) -> bool {
        self.draft.with(|d| {
            d.as_ref()
                .is_some_and(|p| matches!(p.source, crate::workspace::PairSource::Upload { .. }))
        })
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

    /// Shows `pair` as the draft (an upload not kept yet) and runs H-Net on it.
    pub fn show_draft(&self, pair: LabeledPair) {
        self.replace_draft(Some(pair));
        self.run_model();
    }

    /// Keeps the draft (the live twin's pair, a cine frame or an upload) as a workspace pair.
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

    /// Undo (`redo` false) or redo the last mask edit.
    pub fn undo_redo(&self, redo: bool) {
        self.draft.set(None);
        self.edit(|ws| if redo { ws.redo() } else { ws.undo() });
    }
}

/// Ids of both views, for element ids and labels.
pub fn view_index(view: View) -> usize {
    match view {
        View::A => 0,
        View::B => 1,
    }
}
