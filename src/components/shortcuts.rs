//! Keyboard shortcuts, and their list on the page.

use leptos::prelude::*;

use crate::app::{PointerTool, Studio, ViewTransform};

/// The shortcuts: key, what it does.
pub const SHORTCUTS: [(&str, &str); 13] = [
    ("R", "run H-Net"),
    ("A", "use H-Net's masks as the labels"),
    ("B", "brush"),
    ("E", "eraser"),
    ("H", "pan (or drag with the middle button)"),
    ("[ / ]", "smaller / larger brush"),
    ("Ctrl+Z", "undo"),
    ("Ctrl+Shift+Z, Ctrl+Y", "redo"),
    ("M", "show or hide H-Net's masks"),
    ("L", "show or hide the labels"),
    ("Wheel", "zoom at the pointer"),
    ("0", "fit both views"),
    ("N / P", "next / previous pair"),
];

/// Listens to the keyboard on the whole page (not while typing in a field).
pub fn install_shortcuts(studio: Studio) {
    let handle = window_event_listener(leptos::ev::keydown, move |ev: web_sys::KeyboardEvent| {
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
        if typing || ev.alt_key() {
            return;
        }
        let control = ev.ctrl_key() || ev.meta_key();
        let key = ev.key().to_ascii_lowercase();
        let handled = match (control, key.as_str()) {
            (true, "z") => {
                studio.undo_redo(ev.shift_key());
                true
            }
            (true, "y") => {
                studio.undo_redo(true);
                true
            }
            (true, _) => false,
            (false, "r") => {
                studio.run_model();
                true
            }
            (false, "a") => {
                studio.accept_predicted_masks();
                true
            }
            (false, "b") => {
                studio.tool.set(PointerTool::Brush);
                true
            }
            (false, "e") => {
                studio.tool.set(PointerTool::Eraser);
                true
            }
            (false, "h") => {
                studio.tool.set(PointerTool::Pan);
                true
            }
            (false, "[") => {
                studio.brush_radius.update(|r| *r = (*r - 0.5).max(1.0));
                true
            }
            (false, "]") => {
                studio.brush_radius.update(|r| *r = (*r + 0.5).min(20.0));
                true
            }
            (false, "m") => {
                studio.show_prediction.update(|s| *s = !*s);
                true
            }
            (false, "l") => {
                studio.show_label.update(|s| *s = !*s);
                true
            }
            (false, "0") => {
                for t in studio.transforms {
                    t.set(ViewTransform::default());
                }
                true
            }
            (false, "n" | "p") => {
                studio.draft.set(None);
                studio
                    .workspace
                    .update(|ws| ws.step(if key == "n" { 1 } else { -1 }));
                studio.run_model();
                true
            }
            _ => false,
        };
        if handled {
            ev.prevent_default();
        }
    });
    // The page lives as long as the listener.
    std::mem::forget(handle);
}

/// The list of shortcuts.
#[component]
pub fn Shortcuts() -> impl IntoView {
    view! {
        <section class="shortcuts" aria-labelledby="shortcuts-title">
            <h2 id="shortcuts-title">"Keyboard"</h2>
            <dl>
                {SHORTCUTS.iter().map(|(key, what)| view! {
                    <div><dt><kbd>{*key}</kbd></dt><dd>{*what}</dd></div>
                }).collect_view()}
            </dl>
        </section>
    }
}
