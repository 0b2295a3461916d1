//! H-Net Studio in the browser. The crate only has code on wasm32 (built by trunk).
#![cfg(target_arch = "wasm32")]

use leptos::prelude::*;

/// The page.
#[component]
pub fn App() -> impl IntoView {
    view! {
        <main>
            <h1>"H-Net Studio"</h1>
        </main>
    }
}
