//! H-Net Studio in the browser: the page, its components and their state. The crate only has
//! code on wasm32 (trunk builds it; `src/main.rs` mounts [`App`]).
#![cfg(target_arch = "wasm32")]

pub mod bundled;
pub mod compute;

use burn::module::Module;
use hnet_model::{HNet, HNetConfig};
use leptos::prelude::*;

use crate::compute::Backend;

/// What the page knows about its model.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelStatus {
    /// Choosing the backend and loading the weights.
    Loading,
    /// Ready to run.
    Ready {
        /// Where it runs.
        backend: Backend,
        /// Parameter count.
        params: usize,
        /// Input size `[height, width]`.
        input: [usize; 2],
        /// Where the weights came from.
        weights: String,
        /// Time of a first forward pass on a blank stereo pair, ms.
        warmup_ms: f64,
    },
    /// Something went wrong.
    Failed(String),
}

fn now_ms() -> f64 {
    web_sys::window()
        .and_then(|w| w.performance())
        .map(|p| p.now())
        .unwrap_or(0.0)
}

async fn load_model() -> Result<ModelStatus, String> {
    let (device, backend) = compute::select_device(false).await;
    let (model, config, weights) = match bundled::fetch_bytes(bundled::BUNDLED_WEIGHTS).await? {
        Some(bytes) => {
            let (model, config, _) =
                HNet::from_weights_bytes(&bytes, &device, bundled::BUNDLED_WEIGHTS)
                    .map_err(|e| e.to_string())?;
            (model, config, bundled::BUNDLED_WEIGHTS.to_string())
        }
        None => {
            let config = HNetConfig::new().with_image_size([96, 96]);
            let model = config.init(&device).map_err(|e| e.to_string())?;
            (model, config, "untrained (no bundled weights)".to_string())
        }
    };
    let [h, w] = config.image_size;
    let blank = vec![0u8; h * w * 3];
    let start = now_ms();
    model
        .predict_async(
            &[hnet_model::inference::StereoPair {
                view_a: &blank,
                view_b: &blank,
            }],
            [h, w],
            &device,
        )
        .await
        .map_err(|e| e.to_string())?;
    Ok(ModelStatus::Ready {
        backend,
        params: model.num_params(),
        input: config.image_size,
        weights,
        warmup_ms: now_ms() - start,
    })
}

/// The page.
#[component]
pub fn App() -> impl IntoView {
    let status = RwSignal::new(ModelStatus::Loading);
    leptos::task::spawn_local(async move {
        status.set(load_model().await.unwrap_or_else(ModelStatus::Failed));
    });
    view! {
        <main>
            <h1>"H-Net Studio"</h1>
            <p class="lede">
                "Stereo catheter segmentation and 3D tip-force estimation, entirely in your browser."
            </p>
            <section id="model-status" aria-live="polite">
                {move || match status.get() {
                    ModelStatus::Loading => view! { <p data-state="loading">"Loading H-Net…"</p> }.into_any(),
                    ModelStatus::Ready { backend, params, input, weights, warmup_ms } => view! {
                        <dl data-state="ready">
                            <dt>"Backend"</dt><dd id="backend">{backend.label()}</dd>
                            <dt>"Parameters"</dt><dd id="params">{params}</dd>
                            <dt>"Input"</dt><dd>{format!("{} x {} px", input[1], input[0])}</dd>
                            <dt>"Weights"</dt><dd id="weights">{weights}</dd>
                            <dt>"First pass"</dt><dd>{format!("{warmup_ms:.0} ms")}</dd>
                        </dl>
                    }.into_any(),
                    ModelStatus::Failed(message) => view! {
                        <p data-state="failed" class="error">{message}</p>
                    }.into_any(),
                }}
            </section>
        </main>
    }
}
