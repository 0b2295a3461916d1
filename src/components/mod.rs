//! The page's components, one concern each. They share the [`Studio`](crate::studio::Studio) state
//! through Leptos' context.

pub mod catheter_view;
pub mod composer;
pub mod force_panel;
pub mod model_bar;
pub mod pair_list;
pub mod shortcuts;
pub mod sources;
pub mod stereo_view;
