//! What the page asks of the browser: reading the user's files, saving a download, the clock,
//! and letting the page repaint before long work. Nothing here talks to a network.
//!
//! [`JsError`] is how every browser call's failure reaches Rust: the JS error's message, made
//! once from the `JsValue` the call threw.

use js_sys::{Array, Promise, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

/// A browser call that failed: the JS error's message (or, for a call that gave something else
/// than what was asked for, what was missing). The cause below the page's own errors.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct JsError {
    /// What the browser said.
    pub message: String,
    /// The error's name (`QuotaExceededError`, `AbortError`, ...), empty when it has none.
    pub name: String,
}

impl JsError {
    /// A failure the browser did not word itself (`what` is missing or not of the right kind).
    pub fn missing(what: &str) -> Self {
        Self {
            message: what.to_string(),
            name: String::new(),
        }
    }
}

impl From<JsValue> for JsError {
    /// An `Error` (a `DOMException` too) gives its message, a string itself; anything else is
    /// shown as the browser's console would.
    fn from(value: JsValue) -> Self {
        let (message, name) = match value.dyn_ref::<js_sys::Error>() {
            Some(error) => (String::from(error.message()), String::from(error.name())),
            None => (
                value.as_string().unwrap_or_else(|| format!("{value:?}")),
                String::new(),
            ),
        };
        Self { message, name }
    }
}

/// A file the user picked or dropped that could not be read.
#[derive(Debug, thiserror::Error)]
#[error("{file}: cannot be read")]
pub struct FileReadError {
    /// The file's name.
    pub file: String,
    /// What the browser said.
    #[source]
    pub cause: JsError,
}

/// A picked file that could not be used: not read, or its contents refused by the reader it
/// was given to (whose error names the file).
#[derive(Debug, thiserror::Error)]
pub enum PickedFileError<E> {
    /// The browser could not read it.
    #[error(transparent)]
    Read(#[from] FileReadError),
    /// Its contents cannot be used.
    #[error(transparent)]
    Content(E),
}

/// A download that the browser could not offer.
#[derive(Debug, thiserror::Error)]
#[error("cannot save {file}")]
pub struct DownloadError {
    /// The download's file name.
    pub file: String,
    /// What the browser said.
    #[source]
    pub cause: JsError,
}

/// Milliseconds since the page started (`performance.now()`).
pub fn now_ms() -> f64 {
    web_sys::window()
        .and_then(|w| w.performance())
        .map(|p| p.now())
        .unwrap_or(0.0)
}

/// The page address's query (`?a=1&b=2`; empty where it has none), read by [`crate::page_query`].
pub fn page_query() -> String {
    web_sys::window()
        .and_then(|w| w.location().search().ok())
        .unwrap_or_default()
}

/// The bytes of a file the user picked or dropped.
pub async fn read_file(file: &web_sys::File) -> Result<Vec<u8>, FileReadError> {
    let buffer = JsFuture::from(file.array_buffer())
        .await
        .map_err(|e| FileReadError {
            file: file.name(),
            cause: e.into(),
        })?;
    Ok(Uint8Array::new(&buffer).to_vec())
}

/// Reads a picked file and hands its name and bytes to `read` (a decoder or a parser).
pub async fn read_file_with<T, E>(
    file: &web_sys::File,
    read: impl FnOnce(&str, &[u8]) -> Result<T, E>,
) -> Result<T, PickedFileError<E>> {
    let bytes = read_file(file).await?;
    read(&file.name(), &bytes).map_err(PickedFileError::Content)
}

/// The files picked in the `<input type="file">` that `event` came from, in order; the input is
/// emptied, so that picking the same file again is a change again.
pub fn take_picked_files(event: &web_sys::Event) -> Vec<web_sys::File> {
    let Some(input) = event
        .target()
        .and_then(|t| t.dyn_into::<web_sys::HtmlInputElement>().ok())
    else {
        return Vec::new();
    };
    let picked = files(input.files());
    input.set_value("");
    picked
}

/// The first of [`take_picked_files`].
pub fn take_picked_file(event: &web_sys::Event) -> Option<web_sys::File> {
    take_picked_files(event).into_iter().next()
}

/// The files of a file list, in order.
pub fn files(list: Option<web_sys::FileList>) -> Vec<web_sys::File> {
    let Some(list) = list else {
        return Vec::new();
    };
    (0..list.length()).filter_map(|i| list.get(i)).collect()
}

/// Offers `bytes` as a download named `name` (a `blob:` URL on a temporary link; the file is
/// written by the browser, nothing is sent anywhere).
pub fn download(name: &str, bytes: &[u8], mime: &str) -> Result<(), DownloadError> {
    offer_download(name, bytes, mime).map_err(|cause| DownloadError {
        file: name.to_string(),
        cause,
    })
}

fn offer_download(name: &str, bytes: &[u8], mime: &str) -> Result<(), JsError> {
    let parts = Array::of1(&Uint8Array::from(bytes));
    let options = web_sys::BlobPropertyBag::new();
    options.set_type(mime);
    let blob = web_sys::Blob::new_with_u8_array_sequence_and_options(&parts, &options)?;
    let url = web_sys::Url::create_object_url_with_blob(&blob)?;
    let window = web_sys::window().ok_or_else(|| JsError::missing("no window"))?;
    let document = window
        .document()
        .ok_or_else(|| JsError::missing("no document"))?;
    let link: web_sys::HtmlAnchorElement = document
        .create_element("a")?
        .dyn_into()
        .map_err(|_| JsError::missing("cannot create a link"))?;
    link.set_href(&url);
    link.set_download(name);
    link.click();
    // The browser has taken the blob; the URL can go once the click is handled.
    let revoke = Closure::once_into_js(move || {
        let _ = web_sys::Url::revoke_object_url(&url);
    });
    window.set_timeout_with_callback_and_timeout_and_arguments_0(revoke.unchecked_ref(), 10_000)?;
    Ok(())
}

/// Waits for the browser to run its event loop once (so that a busy indicator set just before
/// is painted before long work starts).
pub async fn yield_to_browser() {
    sleep_ms(0).await;
}

/// Waits `ms` milliseconds on the browser's timer, the page answering meanwhile.
pub async fn sleep_ms(ms: i32) {
    let promise = Promise::new(&mut |resolve, _| {
        if let Some(window) = web_sys::window() {
            let _ = window.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms);
        }
    });
    let _ = JsFuture::from(promise).await;
}
