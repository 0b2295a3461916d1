//! What the page tells the user: the latest message (with its undo, if any) and what the page is
//! busy with. Every other store reports through it.

use leptos::prelude::*;

use crate::workspace::RemovedPair;

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

/// The notice bar's state.
#[derive(Clone, Copy)]
pub struct Notices {
    /// The latest message.
    pub notice: RwSignal<Option<Notice>>,
    /// What the page is busy with, if anything (H-Net on a pair, a cine's trace).
    pub busy: RwSignal<Option<String>>,
}

impl Notices {
    /// No message, nothing running.
    pub fn new() -> Self {
        Self {
            notice: RwSignal::new(None),
            busy: RwSignal::new(None),
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

    /// Tells the user something that the notice's button can undo.
    pub fn info_with_undo(&self, text: impl Into<String>, undo: Undoable) {
        self.notice.set(Some(Notice {
            error: false,
            text: text.into(),
            undo: Some(undo),
        }));
    }
}

impl Default for Notices {
    fn default() -> Self {
        Self::new()
    }
}
