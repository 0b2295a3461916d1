//! Files the page ships with, fetched from its own origin (the CSP allows nothing else).

use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

/// Path of the bundled H-Net weights, relative to the page.
pub const BUNDLED_WEIGHTS: &str = "assets/hnet-cpu.bpk";

/// What the bundled weights can and cannot be trusted with, shown beside their force estimate.
/// Keep in step with the evaluation in `assets/MODEL.md`.
pub const BUNDLED_FORCE_CAVEAT: &str = "The bundled weights were trained at the CPU scale \
    (64 x 64 px, 1,600 twin pairs; assets/MODEL.md). On the twin's test split their masks are \
    accurate (catheter IoU 0.92) but their force only coarse (RMSE 0.085 N, R² 0.40): read the \
    arrows as a direction and a rough size, not a measurement.";

/// Fetches `path` from the page's origin. `Ok(None)` when the server has no such file.
pub async fn fetch_bytes(path: &str) -> Result<Option<Vec<u8>>, String> {
    let window = web_sys::window().ok_or("no window")?;
    let response = JsFuture::from(window.fetch_with_str(path))
        .await
        .map_err(|e| format!("cannot fetch {path}: {e:?}"))?;
    let response: web_sys::Response = response
        .dyn_into()
        .map_err(|_| format!("fetching {path} gave no response"))?;
    if response.status() == 404 {
        return Ok(None);
    }
    if !response.ok() {
        return Err(format!("fetching {path}: HTTP {}", response.status()));
    }
    let buffer = JsFuture::from(
        response
            .array_buffer()
            .map_err(|e| format!("reading {path}: {e:?}"))?,
    )
    .await
    .map_err(|e| format!("reading {path}: {e:?}"))?;
    Ok(Some(js_sys::Uint8Array::new(&buffer).to_vec()))
}
