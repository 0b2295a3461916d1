//! The pairs and their labels: the labelling [`Workspace`] (saved to the browser's IndexedDB
//! after every change, so that a reload loses nothing) and the unsaved draft on screen (the live
//! twin's pair, a cine frame or an upload not kept yet).

use leptos::prelude::*;

use super::Notices;
use crate::error_text::with_causes;
use crate::storage;
use crate::workspace::{LabeledPair, PairSource, Workspace};

/// The pairs' state.
#[derive(Clone, Copy)]
pub struct PairStore {
    /// The labelled pairs.
    pub workspace: RwSignal<Workspace>,
    /// The unsaved pair on screen, shown until kept or another pair is selected.
    pub draft: RwSignal<Option<LabeledPair>>,
    /// Counter of drafts made (their ids: `twin-N`, `cine-N`).
    pub draft_serial: RwSignal<u64>,
    /// Where saving failures are reported.
    notices: Notices,
}

impl PairStore {
    /// No pairs, no draft; failures to save reported to `notices`.
    pub fn new(notices: Notices) -> Self {
        Self {
            workspace: RwSignal::new(Workspace::default()),
            draft: RwSignal::new(None),
            draft_serial: RwSignal::new(0),
            notices,
        }
    }

    /// The next draft's serial number.
    pub fn next_draft_serial(&self) -> u64 {
        let serial = self.draft_serial.get_untracked() + 1;
        self.draft_serial.set(serial);
        serial
    }

    /// Calls `f` with the pair on screen: the draft, else the workspace's current pair. Tracks
    /// both.
    pub fn with_shown<R>(&self, f: impl FnOnce(Option<&LabeledPair>) -> R) -> R {
        self.draft.with(|draft| match draft {
            Some(pair) => f(Some(pair)),
            None => self.workspace.with(|ws| f(ws.current())),
        })
    }

    /// The pair on screen, without tracking.
    pub fn shown_untracked(&self) -> Option<LabeledPair> {
        self.draft
            .with_untracked(|d| d.clone())
            .or_else(|| self.workspace.with_untracked(|ws| ws.current().cloned()))
    }

    /// Id of the pair on screen.
    pub fn shown_id(&self) -> Option<String> {
        self.with_shown(|p| p.map(|p| p.id.clone()))
    }

    /// Id of the pair on screen, without tracking.
    pub fn shown_id_untracked(&self) -> Option<String> {
        self.draft
            .with_untracked(|d| d.as_ref().map(|p| p.id.clone()))
            .or_else(|| {
                self.workspace
                    .with_untracked(|ws| ws.current().map(|p| p.id.clone()))
            })
    }

    /// Whether the pair on screen is the unsaved draft.
    pub fn showing_draft(&self) -> bool {
        self.draft.with(Option::is_some)
    }

    /// Whether the pair on screen is an upload not kept yet.
    pub fn showing_upload_draft(&self) -> bool {
        self.draft.with(|d| {
            d.as_ref()
                .is_some_and(|p| matches!(p.source, PairSource::Upload { .. }))
        })
    }

    /// Whether the pair on screen is an unsaved frame of the DICOM cine.
    pub fn showing_cine_frame(&self) -> bool {
        self.draft.with(|d| {
            d.as_ref()
                .is_some_and(|p| matches!(p.source, PairSource::Dicom { .. }))
        })
    }

    /// Saves pair `id` of the workspace to the browser's storage.
    pub fn persist(&self, id: Option<String>) {
        let Some(id) = id else { return };
        let Some(pair) = self.workspace.with_untracked(|ws| ws.pair(&id).cloned()) else {
            return;
        };
        let notices = self.notices;
        leptos::task::spawn_local(async move {
            if let Err(e) = storage::save_pair(&pair).await {
                notices.error(format!(
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
        let store = *self;
        let count = ids.len();
        leptos::task::spawn_local(async move {
            let saved = match metadata {
                Ok(metadata) => storage::save_metadata(metadata).await,
                Err(e) => Err(e),
            };
            match saved {
                Ok(unsaved) => {
                    for id in unsaved {
                        store.persist(Some(id));
                    }
                }
                Err(e) => store.notices.error(format!(
                    "{count} pair(s): changes not saved in the browser: {}",
                    with_causes(&e)
                )),
            }
        });
    }

    /// Applies a workspace change that returns the changed pair's id, and saves that pair.
    pub fn edit(&self, change: impl FnOnce(&mut Workspace) -> Option<String>) {
        let mut changed = None;
        self.workspace.update(|ws| changed = change(ws));
        self.persist(changed);
    }
}
