//! Files the page ships with, fetched from its own origin (the CSP allows nothing else).

use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_futures::JsFuture;

use crate::browser::JsError;

/// Path of the bundled H-Net weights, relative to the page.
pub const BUNDLED_WEIGHTS: &str = "assets/hnet-cpu.bpk";

/// What the bundled weights can and cannot be trusted with, shown beside their force estimate.
/// Keep in step with the evaluation in `assets/MODEL.md`.
pub const BUNDLED_FORCE_CAVEAT: &str = "The bundled weights were trained on the CPU, at \
    128 x 128 px on 84,000 twin pairs, at 224 x 224 px on 10,000 more, and then 6,000 more with a \
    term that teaches the masks' sub-pixel edges (assets/MODEL.md). On fresh twin pairs their \
    masks are accurate (catheter IoU 0.94-0.95 on the bench, 0.86-0.92 on other catheters, \
    poses, C-arm angles and chest radiographs, as long as the catheter comes up from the bottom \
    of the view, as in every training scene: one entering from the top or a side loses its shaft \
    unless \"Catheter enters from\" names or finds the edge, when each view is turned for H-Net \
    and its own force is not read) but their force only coarse (RMSE 0.067 N, R² 0.63), and \
    learned on the bench pose alone: read the arrows as a direction and a rough size, not a \
    measurement. The physics estimate, fitted to these masks and read blind (the catalogue's \
    catheter, the base fitted near the bench fixture's pose), is closer across the catheter \
    (R² 0.88 and 0.90 on x and y on the bench) but not along it (Fz: R² 0.51). The Combined row \
    (each axis weighted by the inverse of its measured error; shown when the rod was fitted to \
    these masks: on a twin pair, choose H-Net's masks in the 3D panel) is the closest on twin \
    bench pairs: R² 0.93 / 0.93 / 0.74, RMSE 0.037 N per axis, its 90 % interval holding 88-91 % \
    of true forces; the verdict reads it where it is shown. For uploads the catheter is the twin \
    tab's and nothing was measured.";

/// A file of the page's own that could not be fetched.
#[derive(Debug, thiserror::Error)]
pub enum FetchError {
    /// The request failed (no network, refused by the CSP, no answer).
    #[error("cannot fetch {path}")]
    Request {
        /// The file, relative to the page.
        path: String,
        /// What the browser said.
        #[source]
        cause: JsError,
    },
    /// The server answered with an error.
    #[error("fetching {path}: HTTP {status}")]
    Status {
        /// The file, relative to the page.
        path: String,
        /// The HTTP status.
        status: u16,
    },
    /// The answer's body could not be read.
    #[error("reading {path}")]
    Body {
        /// The file, relative to the page.
        path: String,
        /// What the browser said.
        #[source]
        cause: JsError,
    },
}

/// Fetches `path` from the page's origin. `Ok(None)` when the server has no such file.
pub async fn fetch_bytes(path: &str) -> Result<Option<Vec<u8>>, FetchError> {
    let request = |cause: JsError| FetchError::Request {
        path: path.to_string(),
        cause,
    };
    let body = |cause: JsValue| FetchError::Body {
        path: path.to_string(),
        cause: cause.into(),
    };
    let window = web_sys::window().ok_or_else(|| request(JsError::missing("no window")))?;
    let response: web_sys::Response = JsFuture::from(window.fetch_with_str(path))
        .await
        .map_err(|e| request(e.into()))?
        .dyn_into()
        .map_err(|_| request(JsError::missing("the answer is not a response")))?;
    if response.status() == 404 {
        return Ok(None);
    }
    if !response.ok() {
        return Err(FetchError::Status {
            path: path.to_string(),
            status: response.status(),
        });
    }
    let buffer = JsFuture::from(response.array_buffer().map_err(body)?)
        .await
        .map_err(body)?;
    Ok(Some(js_sys::Uint8Array::new(&buffer).to_vec()))
}
