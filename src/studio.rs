//! The page's state, split by concern into stores that are created once and handed to the
//! components that show them, each on its own:
//!
//! | store | concern |
//! | --- | --- |
//! | [`Notices`] | the message bar and what the page is busy with |
//! | [`PairStore`] | the labelled pairs, saved in the browser, and the unsaved draft on screen |
//! | [`NetworkStore`] | the network, its engine and workers, and its predictions |
//! | [`DisplaySettings`] | how the views are shown and what the pointer does on them |
//! | [`TwinStore`] | the live twin, the catheter and its reconstruction in 3D |
//! | [`CineStore`] | the DICOM cine, its playback and its force trace |
//! | [`TuningStore`] | the fine-tune in its worker and the weights kept from it |
//!
//! [`Studio`] holds no state of its own: it is the actions that change more than one store
//! (run H-Net on the pair on screen, keep a draft, play and trace a cine, fine-tune, delete and
//! restore pairs, undo), each in the file of its concern. Components read the stores they are
//! given and call these actions; none reaches into the others' state through it.

use leptos::prelude::*;

use crate::engine::Prediction;
use crate::error_text::with_causes;
use crate::storage;
use crate::workspace::{LabeledPair, Workspace};
use hnet_twin::simulator::sensor_plate::ContactError;

mod catheter;
mod cine;
mod display;
mod model;
mod notices;
mod pairs;
mod tuning;
mod twin;

pub use catheter::{CatheterReading, install_reconstruction};
pub use cine::CineStore;
pub use display::{CANVAS_SIDE, DisplaySettings, PointerTool, SourceTab, ViewTransform};
pub use model::{ModelState, NetworkStore, load_model};
pub use notices::{Notice, Notices, Undoable};
pub use pairs::PairStore;
pub use tuning::{KEPT_NAME, TuningProgress, TuningResult, TuningState, TuningStore};
pub use twin::TwinStore;

/// The actions across the page's stores.
#[derive(Clone, Copy)]
pub struct Studio {
    notices: Notices,
    pairs: PairStore,
    network: NetworkStore,
    display: DisplaySettings,
    twin: TwinStore,
    cine: CineStore,
    tuning: TuningStore,
}

/// Every store of a page that has just opened: no model yet, no pairs.
#[derive(Clone, Copy)]
pub struct Stores {
    /// The message bar.
    pub notices: Notices,
    /// The pairs and the draft.
    pub pairs: PairStore,
    /// The network and its predictions.
    pub network: NetworkStore,
    /// How the views are shown.
    pub display: DisplaySettings,
    /// The twin and the catheter in 3D.
    pub twin: TwinStore,
    /// The cine.
    pub cine: CineStore,
    /// The fine-tune.
    pub tuning: TuningStore,
    /// H-Net's prediction of the pair on screen, once made (the one memo every component that
    /// shows it reads).
    pub shown_prediction: Memo<Option<Prediction>>,
}

impl Stores {
    /// The stores of a page that has just opened.
    pub fn new() -> Self {
        let notices = Notices::new();
        let pairs = PairStore::new(notices);
        let network = NetworkStore::new();
        Self {
            notices,
            pairs,
            network,
            display: DisplaySettings::new(),
            twin: TwinStore::new(),
            cine: CineStore::new(),
            tuning: TuningStore::new(),
            shown_prediction: network.shown_prediction(pairs),
        }
    }

    /// The actions across these stores.
    pub fn studio(&self) -> Studio {
        Studio {
            notices: self.notices,
            pairs: self.pairs,
            network: self.network,
            display: self.display,
            twin: self.twin,
            cine: self.cine,
            tuning: self.tuning,
        }
    }
}

impl Default for Stores {
    fn default() -> Self {
        Self::new()
    }
}

impl Studio {
    /// Deletes the pair on screen, from the page and the browser's storage; the notice offers
    /// to undo it.
    pub fn delete_current_pair(&self) {
        let mut removed = None;
        self.pairs.draft.set(None);
        self.pairs
            .workspace
            .update(|ws| removed = ws.remove_current());
        let Some(removed) = removed else { return };
        let id = removed.pair.id.clone();
        self.network.predictions.update(|p| {
            p.remove(&id);
        });
        let notices = self.notices;
        leptos::task::spawn_local(async move {
            match storage::delete_pair(&id).await {
                Ok(()) => notices.info_with_undo(
                    format!("{id} deleted"),
                    Undoable::Deletion(Box::new(removed)),
                ),
                Err(e) => notices.error(format!(
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
                self.pairs.draft.set(None);
                self.pairs
                    .workspace
                    .update(|ws| restored = ws.restore(*removed));
                match restored {
                    Some(id) => {
                        self.pairs.persist(Some(id.clone()));
                        self.notices.info(format!("{id} restored"));
                        self.run_model();
                    }
                    None => self.notices.error(format!(
                        "{id} cannot be restored: a pair with that id was added since"
                    )),
                }
            }
        }
    }

    /// Shows `pair` as the draft (an upload not kept yet) and runs H-Net on it.
    pub fn show_draft(&self, pair: LabeledPair) {
        self.replace_draft(Some(pair));
        self.run_model();
    }

    /// Keeps the draft (the live twin's pair, a cine frame or an upload) as a workspace pair.
    pub fn keep_draft(&self) {
        let Some(mut pair) = self.pairs.draft.get_untracked() else {
            return;
        };
        let draft_id = pair.id.clone();
        pair.id = self.pairs.workspace.with_untracked(Workspace::next_id);
        let id = pair.id.clone();
        self.network.predictions.update(|p| {
            if let Some(prediction) = p.remove(&draft_id) {
                p.insert(id.clone(), prediction);
            }
        });
        self.pairs.draft.set(None);
        self.pairs.workspace.update(|ws| ws.add(pair));
        self.pairs.persist(Some(id.clone()));
        self.notices
            .info(format!("{id} added to the labeled pairs"));
    }

    /// Renders the live twin with the current sliders and background as the draft.
    pub fn render_twin(&self) {
        let controls = self.twin.controls.get_untracked();
        let id = format!("twin-{}", self.pairs.next_draft_serial());
        let result = self
            .twin
            .background
            .with_untracked(|bg| controls.render(id, bg));
        match result {
            Ok(pair) => self.replace_draft(Some(pair)),
            Err(ContactError::BeyondSensorRange {
                force_n,
                max_force_n,
            }) => self.notices.error(format!(
                "this press gives {force_n:.2} N, beyond the bench sensor's {max_force_n} N \
                 range: press less or tilt the plate less"
            )),
            Err(e) => self.notices.error(format!(
                "the catheter does not settle under this load ({}); try a smaller force or a \
                 stiffer catheter",
                with_causes(&e)
            )),
        }
    }

    /// Shows `pair` as the unsaved draft (or none), forgetting the previous draft's prediction.
    fn replace_draft(&self, pair: Option<LabeledPair>) {
        if let Some(old) = self
            .pairs
            .draft
            .with_untracked(|d| d.as_ref().map(|p| p.id.clone()))
        {
            self.network.predictions.update(|p| {
                p.remove(&old);
            });
        }
        self.pairs.draft.set(pair);
    }

    /// The id of the pair on screen for labeling: the draft is kept first (labels are only
    /// given to kept pairs).
    pub fn labeled_pair_id(&self) -> Option<String> {
        if self.pairs.draft.with_untracked(Option::is_some) {
            self.keep_draft();
        }
        self.pairs
            .workspace
            .with_untracked(|ws| ws.current().map(|p| p.id.clone()))
    }

    /// Uses H-Net's masks of the pair on screen as its label masks (one undo step).
    pub fn accept_predicted_masks(&self) {
        let Some(id) = self.labeled_pair_id() else {
            return;
        };
        let Some(prediction) = self
            .network
            .predictions
            .with_untracked(|p| p.get(&id).cloned())
        else {
            self.notices
                .error("run H-Net first: there are no predicted masks for this pair");
            return;
        };
        let masks = [
            hnet_units::mask::binarize(&prediction.mask_a),
            hnet_units::mask::binarize(&prediction.mask_b),
        ];
        self.pairs.edit(|ws| ws.set_masks(masks));
        self.display.show_label.set(true);
    }

    /// Opens source panel `which`: the cine pauses; the cine's frame, or the twin's pair (on
    /// the background being composed, for that panel), is shown and H-Net runs on it.
    pub fn open_source(&self, which: SourceTab) {
        self.display.tab.set(which);
        self.cine.stop_playback();
        if which == SourceTab::Background {
            // Show the catheter on the background being composed.
            let xray = self
                .twin
                .background
                .with_untracked(|bg| bg.style.modality());
            self.twin.controls.update(|t| t.modality = xray);
        }
        match which {
            SourceTab::Images => {}
            SourceTab::Cine => {
                self.show_cine_frame();
                self.run_model();
            }
            SourceTab::Twin | SourceTab::Background => {
                self.render_twin();
                self.run_model();
            }
        }
    }

    /// Undo (`redo` false) or redo the last mask edit.
    pub fn undo_redo(&self, redo: bool) {
        self.pairs.draft.set(None);
        self.pairs
            .edit(|ws| if redo { ws.redo() } else { ws.undo() });
    }
}
