//! The page's components, one concern each. Each takes what it shows as props: the store of its
//! concern ([`crate::studio`]), narrow signals of others, and [`Studio`](crate::studio::Studio)
//! for the actions that change more than one store; none reads a context
//! (`src/page_architecture.rs` checks it).

pub mod catheter_view;
pub mod cine_panel;
pub mod composer;
pub mod fine_tune_panel;
pub mod force_panel;
pub mod force_trace;
pub mod model_bar;
pub mod pair_list;
pub mod shortcuts;
pub mod sources;
pub mod stereo_view;
pub mod upload_geometry;

use leptos::prelude::event_target_value;

/// The `input` handler of a range slider: `set` gets the slider's value.
pub(crate) fn on_slider(set: impl Fn(f64) + 'static) -> impl Fn(web_sys::Event) + 'static {
    move |ev| {
        if let Ok(value) = event_target_value(&ev).parse::<f64>() {
            set(value);
        }
    }
}
