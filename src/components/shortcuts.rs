//! The page-wide keyboard shortcuts ([`crate::keymap`]'s `Page` scope), and the help panel that
//! lists every shortcut.

use leptos::prelude::*;

use crate::keymap::{Command, KEYMAP, Scope, command};
use crate::studio::{DisplaySettings, PairStore, PointerTool, Studio};

/// Carries out a page-wide command.
fn execute(studio: Studio, pairs: PairStore, display: DisplaySettings, command: Command) {
    match command {
        Command::RunModel => studio.run_model(),
        Command::AcceptMasks => studio.accept_predicted_masks(),
        Command::Brush => display.tool.set(PointerTool::Brush),
        Command::Eraser => display.tool.set(PointerTool::Eraser),
        Command::Pan => display.tool.set(PointerTool::Pan),
        Command::WindowLevel => display.tool.set(PointerTool::WindowLevel),
        Command::PlayPause => studio.toggle_play(),
        Command::NextFrame => studio.step_cine(1),
        Command::PreviousFrame => studio.step_cine(-1),
        Command::SmallerBrush => display.brush_radius.update(|r| *r = (*r - 0.5).max(1.0)),
        Command::LargerBrush => display.brush_radius.update(|r| *r = (*r + 0.5).min(20.0)),
        Command::Undo => studio.undo_redo(false),
        Command::Redo => studio.undo_redo(true),
        Command::ToggleMasks => display.show_prediction.update(|s| *s = !*s),
        Command::ToggleLabels => display.show_label.update(|s| *s = !*s),
        Command::FitViews => display.fit_views(),
        Command::NextPair | Command::PreviousPair => {
            pairs.draft.set(None);
            let step = if command == Command::NextPair { 1 } else { -1 };
            pairs.workspace.update(|ws| ws.step(step));
            studio.run_model();
        }
        // Keys of focused elements, handled there.
        Command::Left
        | Command::Right
        | Command::Up
        | Command::Down
        | Command::Grow
        | Command::Shrink
        | Command::First
        | Command::Last
        | Command::ResetView
        | Command::ToggleProjection => {}
    }
}

/// Listens to the keyboard on the whole page (not while typing in a field).
pub fn install_shortcuts(studio: Studio, pairs: PairStore, display: DisplaySettings) {
    let handle = window_event_listener(leptos::ev::keydown, move |ev: web_sys::KeyboardEvent| {
        // Enter opens a focused file picker as Space does (Chromium opens it on Space only).
        if ev.key() == "Enter"
            && let Some(input) = ev
                .target()
                .and_then(|t| wasm_bindgen::JsCast::dyn_into::<web_sys::HtmlInputElement>(t).ok())
                .filter(|input| input.type_() == "file")
        {
            ev.prevent_default();
            input.click();
            return;
        }
        let typing = ev
            .target()
            .and_then(|t| wasm_bindgen::JsCast::dyn_into::<web_sys::HtmlElement>(t).ok())
            .is_some_and(|e| {
                let tag = e.tag_name().to_ascii_lowercase();
                (tag == "input"
                    && !matches!(
                        e.get_attribute("type").as_deref(),
                        Some("range" | "checkbox" | "radio" | "button" | "file")
                    ))
                    || tag == "textarea"
                    || tag == "select"
                    || e.is_content_editable()
            });
        if typing || ev.alt_key() || ev.default_prevented() {
            return;
        }
        let control = ev.ctrl_key() || ev.meta_key();
        if let Some(command) = command(Scope::Page, &ev.key(), control, ev.shift_key()) {
            ev.prevent_default();
            execute(studio, pairs, display, command);
        }
    });
    // The page lives as long as the listener.
    std::mem::forget(handle);
}

/// The list of shortcuts.
#[component]
pub fn Shortcuts() -> impl IntoView {
    view! {
        <details class="shortcuts" id="shortcuts">
            <summary><h2>"Keyboard shortcuts"</h2></summary>
            <dl>
                {KEYMAP.iter().map(|binding| view! {
                    <div><dt><kbd>{binding.keys}</kbd></dt><dd>{binding.what}</dd></div>
                }).collect_view()}
            </dl>
        </details>
    }
}
