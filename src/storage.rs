//! Keeping the labeling work in the browser (IndexedDB), so that it survives reloads. Nothing is
//! sent anywhere.
//!
//! One record per pair in the object store `pairs`, keyed by the pair's id: its metadata as JSON
//! and its images and masks as PNG bytes.

use js_sys::{Array, Object, Promise, Reflect, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{IdbDatabase, IdbRequest, IdbTransactionMode};

use hnet_twin::dataset::{ImageRef, Split, encode_png};

use crate::error_text::with_causes;
use crate::imaging::WORK_SIZE;
use crate::workspace::{LabeledPair, PairSource};

const DATABASE: &str = "hnet-studio";
const STORE: &str = "pairs";

fn js_error(context: &str, e: JsValue) -> String {
    format!(
        "{context}: {}",
        e.as_string().unwrap_or_else(|| format!("{e:?}"))
    )
}

/// Waits for an IndexedDB request to succeed or fail.
async fn settled(request: &IdbRequest) -> Result<JsValue, String> {
    let promise = Promise::new(&mut |resolve, reject| {
        let ok_request = request.clone();
        let on_success = Closure::once_into_js(move |_: web_sys::Event| {
            let _ = resolve.call1(
                &JsValue::NULL,
                &ok_request.result().unwrap_or(JsValue::NULL),
            );
        });
        let err_request = request.clone();
        let on_error = Closure::once_into_js(move |_: web_sys::Event| {
            let message = err_request
                .error()
                .ok()
                .flatten()
                .map(|e| e.message())
                .unwrap_or_else(|| "unknown error".into());
            let _ = reject.call1(&JsValue::NULL, &JsValue::from_str(&message));
        });
        request.set_onsuccess(Some(on_success.unchecked_ref()));
        request.set_onerror(Some(on_error.unchecked_ref()));
    });
    JsFuture::from(promise)
        .await
        .map_err(|e| js_error("browser storage", e))
}

async fn open() -> Result<IdbDatabase, String> {
    let factory = web_sys::window()
        .ok_or("no window")?
        .indexed_db()
        .map_err(|e| js_error("browser storage", e))?
        .ok_or("this browser has no IndexedDB")?;
    let request = factory
        .open_with_u32(DATABASE, 1)
        .map_err(|e| js_error("browser storage", e))?;
    let upgrade = request.clone();
    let on_upgrade = Closure::once_into_js(move |_: web_sys::Event| {
        if let Ok(result) = upgrade.result()
            && let Ok(db) = result.dyn_into::<IdbDatabase>()
            && !db.object_store_names().contains(STORE)
        {
            let _ = db.create_object_store(STORE);
        }
    });
    request.set_onupgradeneeded(Some(on_upgrade.unchecked_ref()));
    settled(&request)
        .await?
        .dyn_into::<IdbDatabase>()
        .map_err(|_| "browser storage did not open".to_string())
}

fn png(pixels: &[u8], channels: usize) -> Uint8Array {
    let bytes = encode_png(ImageRef {
        width: WORK_SIZE,
        height: WORK_SIZE,
        channels,
        pixels,
    });
    Uint8Array::from(bytes.as_slice())
}

#[derive(serde::Serialize, serde::Deserialize)]
struct Metadata {
    id: String,
    source: PairSource,
    masks_labeled: bool,
    force_n: Option<[f32; 3]>,
    /// Absent in records saved before splits were kept (they get one at the next export).
    #[serde(default)]
    split: Option<Split>,
}

/// Saves (or replaces) a pair.
pub async fn save_pair(pair: &LabeledPair) -> Result<(), String> {
    let db = open().await?;
    let record = Object::new();
    let metadata = serde_json::to_string(&Metadata {
        id: pair.id.clone(),
        source: pair.source.clone(),
        masks_labeled: pair.masks_labeled,
        force_n: pair.force_n,
        split: pair.split,
    })
    .map_err(|e| with_causes(&e))?;
    let set = |key: &str, value: &JsValue| Reflect::set(&record, &key.into(), value);
    set("metadata", &JsValue::from_str(&metadata)).map_err(|e| js_error("saving", e))?;
    set("view_a", &png(&pair.view_a, 3)).map_err(|e| js_error("saving", e))?;
    set("view_b", &png(&pair.view_b, 3)).map_err(|e| js_error("saving", e))?;
    set("mask_a", &png(&pair.mask_a, 1)).map_err(|e| js_error("saving", e))?;
    set("mask_b", &png(&pair.mask_b, 1)).map_err(|e| js_error("saving", e))?;
    let store = db
        .transaction_with_str_and_mode(STORE, IdbTransactionMode::Readwrite)
        .and_then(|t| t.object_store(STORE))
        .map_err(|e| js_error("saving", e))?;
    let request = store
        .put_with_key(&record, &JsValue::from_str(&pair.id))
        .map_err(|e| js_error("saving", e))?;
    settled(&request).await.map(|_| ())
}

/// Deletes a pair.
pub async fn delete_pair(id: &str) -> Result<(), String> {
    let db = open().await?;
    let store = db
        .transaction_with_str_and_mode(STORE, IdbTransactionMode::Readwrite)
        .and_then(|t| t.object_store(STORE))
        .map_err(|e| js_error("deleting", e))?;
    let request = store
        .delete(&JsValue::from_str(id))
        .map_err(|e| js_error("deleting", e))?;
    settled(&request).await.map(|_| ())
}

fn decode(value: &JsValue, key: &str, channels: usize) -> Result<Vec<u8>, String> {
    let bytes = Reflect::get(value, &key.into())
        .map_err(|e| js_error("reading", e))?
        .dyn_into::<Uint8Array>()
        .map_err(|_| format!("stored pair lacks `{key}`"))?
        .to_vec();
    let image = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map_err(|e| format!("stored `{key}` is damaged: {e}"))?;
    Ok(if channels == 3 {
        image.to_rgb8().into_raw()
    } else {
        image.to_luma8().into_raw()
    })
}

/// Loads every saved pair, sorted by id. Damaged records are skipped and reported.
pub async fn load_pairs() -> Result<(Vec<LabeledPair>, Vec<String>), String> {
    let db = open().await?;
    let store = db
        .transaction_with_str(STORE)
        .and_then(|t| t.object_store(STORE))
        .map_err(|e| js_error("reading", e))?;
    let request = store.get_all().map_err(|e| js_error("reading", e))?;
    let records: Array = settled(&request)
        .await?
        .dyn_into()
        .map_err(|_| "stored pairs are not a list".to_string())?;
    let mut pairs = Vec::new();
    let mut problems = Vec::new();
    for value in records.iter() {
        let parsed = (|| -> Result<LabeledPair, String> {
            let metadata: Metadata = serde_json::from_str(
                &Reflect::get(&value, &"metadata".into())
                    .ok()
                    .and_then(|m| m.as_string())
                    .ok_or("no metadata")?,
            )
            .map_err(|e| with_causes(&e))?;
            Ok(LabeledPair {
                id: metadata.id,
                source: metadata.source,
                view_a: decode(&value, "view_a", 3)?,
                view_b: decode(&value, "view_b", 3)?,
                mask_a: decode(&value, "mask_a", 1)?,
                mask_b: decode(&value, "mask_b", 1)?,
                masks_labeled: metadata.masks_labeled,
                force_n: metadata.force_n,
                split: metadata.split,
            })
        })();
        match parsed {
            Ok(pair) => pairs.push(pair),
            Err(e) => problems.push(e),
        }
    }
    pairs.sort_by(|a, b| a.id.cmp(&b.id));
    Ok((pairs, problems))
}
