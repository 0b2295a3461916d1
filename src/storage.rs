//! Keeping the labeling work in the browser (IndexedDB), so that it survives reloads. Nothing is
//! sent anywhere.
//!
//! One record per pair in the object store `pairs`, keyed by the pair's id: its metadata as JSON
//! and its images and masks as PNG bytes. A save or a deletion counts as done only once its
//! transaction has committed: a write that the browser refuses (its storage full) or that a
//! reload interrupts leaves the pair's previous record whole, and every other record untouched.

use js_sys::{Array, Object, Promise, Reflect, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{IdbDatabase, IdbObjectStore, IdbRequest, IdbTransaction, IdbTransactionMode};

use crate::browser::JsError;
pub use crate::stored_pair::DamagedRecord;
use crate::stored_pair::{self, IMAGE_KEYS, METADATA_KEY};
use crate::workspace::LabeledPair;
use hnet_twin::reconstruction::catalogue::StiffnessCalibration;

const DATABASE: &str = "hnet-studio";
/// The database's version: 2 added the store of fine-tuned weights.
const VERSION: u32 = 2;
const STORE: &str = "pairs";
/// What the page reads pairs with, as the user set it: the fine-tuned weights kept
/// ([`FINE_TUNED_KEY`]) and the catheter's calibration ([`CALIBRATION_KEY`]), a record each.
const MODELS: &str = "models";
const FINE_TUNED_KEY: &str = "fine-tuned";
const CALIBRATION_KEY: &str = "catheter-calibration";

/// The browser's storage of pairs could not be used.
#[derive(Debug, thiserror::Error)]
pub enum StorageError {
    /// The browser offers no IndexedDB (or not to this page).
    #[error("this browser has no IndexedDB")]
    NoIndexedDb,
    /// The database could not be opened.
    #[error("browser storage (IndexedDB `hnet-studio`) cannot be opened")]
    Open(#[source] JsError),
    /// The browser refused the write: the page's storage is full.
    #[error(
        "the browser's storage for this page is full: this change stays on the page until it is \
         closed; export the labels (zip) and delete pairs, or free space in the browser's site \
         settings. Pairs saved before are kept"
    )]
    Full(#[source] JsError),
    /// A request to the store of pairs was refused or failed.
    #[error("{action} the browser's store `pairs` failed")]
    Request {
        /// What was asked: `saving in`, `deleting from` or `reading`.
        action: &'static str,
        /// What the browser said.
        #[source]
        cause: JsError,
    },
    /// A request to the store of fine-tuned weights was refused or failed.
    #[error("{action} the browser's store of fine-tuned weights failed")]
    ModelRequest {
        /// What was asked: `saving in` or `reading`.
        action: &'static str,
        /// What the browser said.
        #[source]
        cause: JsError,
    },
    /// A pair's metadata could not be written as JSON.
    #[error("{id}: its metadata cannot be written")]
    Metadata {
        /// The pair.
        id: String,
        /// Why.
        #[source]
        cause: serde_json::Error,
    },
}

impl StorageError {
    /// The error of a failed request, for `map_err`.
    fn request(action: &'static str) -> impl Fn(JsValue) -> Self {
        Self::failed(move |cause| Self::Request { action, cause })
    }

    /// The error of a failed request: a full storage named as such, any other failure `other`.
    fn failed(other: impl Fn(JsError) -> Self) -> impl Fn(JsValue) -> Self {
        move |e| {
            let cause = JsError::from(e);
            if cause.name == "QuotaExceededError" {
                Self::Full(cause)
            } else {
                other(cause)
            }
        }
    }
}

/// Waits for an IndexedDB request to succeed or fail (with the request's `DOMException`).
async fn settled(request: &IdbRequest) -> Result<JsValue, JsValue> {
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
            let error = err_request
                .error()
                .ok()
                .flatten()
                .map_or_else(|| JsValue::from_str("unknown error"), JsValue::from);
            let _ = reject.call1(&JsValue::NULL, &error);
        });
        request.set_onsuccess(Some(on_success.unchecked_ref()));
        request.set_onerror(Some(on_error.unchecked_ref()));
    });
    JsFuture::from(promise).await
}

/// Waits for a transaction to commit, or fails with why it was aborted (the transaction's own
/// error, such as `QuotaExceededError`, which its requests may not report).
async fn committed(transaction: &IdbTransaction) -> Result<(), JsValue> {
    let promise = Promise::new(&mut |resolve, reject| {
        let on_complete = Closure::once_into_js(move |_: web_sys::Event| {
            let _ = resolve.call0(&JsValue::NULL);
        });
        let failed = transaction.clone();
        let reject_with = move |_: web_sys::Event| {
            let error = failed.error().map_or_else(
                || JsValue::from_str("the transaction was aborted"),
                JsValue::from,
            );
            let _ = reject.call1(&JsValue::NULL, &error);
        };
        let on_abort = Closure::once_into_js(reject_with.clone());
        let on_error = Closure::once_into_js(reject_with);
        transaction.set_oncomplete(Some(on_complete.unchecked_ref()));
        transaction.set_onabort(Some(on_abort.unchecked_ref()));
        transaction.set_onerror(Some(on_error.unchecked_ref()));
    });
    JsFuture::from(promise).await.map(drop)
}

async fn open() -> Result<IdbDatabase, StorageError> {
    let open_error = |e: JsValue| StorageError::Open(e.into());
    let factory = web_sys::window()
        .ok_or_else(|| StorageError::Open(JsError::missing("no window")))?
        .indexed_db()
        .map_err(open_error)?
        .ok_or(StorageError::NoIndexedDb)?;
    let request = factory
        .open_with_u32(DATABASE, VERSION)
        .map_err(open_error)?;
    let upgrade = request.clone();
    let on_upgrade = Closure::once_into_js(move |_: web_sys::Event| {
        if let Ok(result) = upgrade.result()
            && let Ok(db) = result.dyn_into::<IdbDatabase>()
        {
            for name in [STORE, MODELS] {
                if !db.object_store_names().contains(name) {
                    let _ = db.create_object_store(name);
                }
            }
        }
    });
    request.set_onupgradeneeded(Some(on_upgrade.unchecked_ref()));
    settled(&request)
        .await
        .map_err(open_error)?
        .dyn_into::<IdbDatabase>()
        .map_err(|_| StorageError::Open(JsError::missing("no database was opened")))
}

/// The metadata record of `pair`, as JSON.
fn metadata_json(pair: &LabeledPair) -> Result<String, StorageError> {
    stored_pair::metadata_json(pair).map_err(|cause| StorageError::Metadata {
        id: pair.id.clone(),
        cause,
    })
}

/// Saves (or replaces) a pair.
pub async fn save_pair(pair: &LabeledPair) -> Result<(), StorageError> {
    let db = open().await?;
    let record = Object::new();
    let metadata = metadata_json(pair)?;
    let failed = StorageError::request("saving in");
    let set = |key: &str, value: &JsValue| Reflect::set(&record, &key.into(), value);
    set(METADATA_KEY, &JsValue::from_str(&metadata)).map_err(&failed)?;
    for ((key, _), png) in IMAGE_KEYS.iter().zip(stored_pair::image_pngs(pair)) {
        set(key, &Uint8Array::from(png.as_slice())).map_err(&failed)?;
    }
    let transaction = db
        .transaction_with_str_and_mode(STORE, IdbTransactionMode::Readwrite)
        .map_err(&failed)?;
    transaction
        .object_store(STORE)
        .and_then(|store| store.put_with_key(&record, &JsValue::from_str(&pair.id)))
        .map_err(&failed)?;
    committed(&transaction).await.map_err(failed)
}

/// A pair's metadata as it is stored, for [`save_metadata`]: small, so that many can be
/// gathered without copying the pairs' images.
pub struct PairMetadata {
    id: String,
    json: String,
}

impl PairMetadata {
    /// The metadata of `pair`.
    pub fn of(pair: &LabeledPair) -> Result<Self, StorageError> {
        Ok(Self {
            id: pair.id.clone(),
            json: metadata_json(pair)?,
        })
    }
}

/// Pairs whose metadata one transaction of [`save_metadata`] puts back: each record read and
/// written is structured-cloned on the page's thread (126 KiB of PNGs for a 224 px pair), so a
/// transaction of all of 1,000 pairs stopped the page for 5 s; batches of this many let it answer
/// in between.
const METADATA_BATCH: usize = 25;

/// Saves what changed in pairs whose images and masks did not (a split, a force label): each
/// stored record is read and put back with the pair's new metadata, without encoding any image
/// again, in transactions of `METADATA_BATCH` pairs. Returns the ids of pairs that have no
/// stored record (a save that failed earlier): those need [`save_pair`]. On an error, the
/// batches before it are saved and the failing one is not.
pub async fn save_metadata(metadata: Vec<PairMetadata>) -> Result<Vec<String>, StorageError> {
    let mut unsaved = Vec::new();
    if metadata.is_empty() {
        return Ok(unsaved);
    }
    let db = open().await?;
    for batch in metadata.chunks(METADATA_BATCH) {
        unsaved.extend(save_metadata_batch(&db, batch).await?);
    }
    Ok(unsaved)
}

/// One transaction of [`save_metadata`]; nothing of it is saved unless it commits.
async fn save_metadata_batch(
    db: &IdbDatabase,
    batch: &[PairMetadata],
) -> Result<Vec<String>, StorageError> {
    let failed = StorageError::request("saving in");
    let transaction = db
        .transaction_with_str_and_mode(STORE, IdbTransactionMode::Readwrite)
        .map_err(&failed)?;
    let store = transaction.object_store(STORE).map_err(&failed)?;
    let unsaved = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
    for PairMetadata { id, json } in batch {
        let request = store.get(&JsValue::from_str(id)).map_err(&failed)?;
        let (read, store, transaction, unsaved) = (
            request.clone(),
            store.clone(),
            transaction.clone(),
            unsaved.clone(),
        );
        let (id, json) = (id.clone(), json.clone());
        // The record is put back from the read's own success event, while the transaction is
        // still active (awaiting the read would let it commit in between).
        let on_read = Closure::once_into_js(move |_: web_sys::Event| {
            let record = read.result().unwrap_or(JsValue::UNDEFINED);
            if !record.is_object() {
                unsaved.borrow_mut().push(id);
                return;
            }
            let key = JsValue::from_str(&id);
            let written = Reflect::set(&record, &METADATA_KEY.into(), &JsValue::from_str(&json))
                .and_then(|_| store.put_with_key(&record, &key));
            if written.is_err() {
                // Fails the whole transaction, which `committed` then reports.
                let _ = transaction.abort();
            }
        });
        request.set_onsuccess(Some(on_read.unchecked_ref()));
    }
    committed(&transaction).await.map_err(failed)?;
    Ok(unsaved.take())
}

/// The store of pairs, in a transaction of `mode`.
fn store(db: &IdbDatabase, mode: IdbTransactionMode) -> Result<IdbObjectStore, JsValue> {
    db.transaction_with_str_and_mode(STORE, mode)?
        .object_store(STORE)
}

/// Deletes a pair.
pub async fn delete_pair(id: &str) -> Result<(), StorageError> {
    let db = open().await?;
    let failed = StorageError::request("deleting from");
    let transaction = db
        .transaction_with_str_and_mode(STORE, IdbTransactionMode::Readwrite)
        .map_err(&failed)?;
    transaction
        .object_store(STORE)
        .and_then(|store| store.delete(&JsValue::from_str(id)))
        .map_err(&failed)?;
    committed(&transaction).await.map_err(failed)
}

/// A stored record as a pair ([`stored_pair::read_record`] over the record's values).
fn read_record(value: &JsValue) -> Result<LabeledPair, DamagedRecord> {
    let metadata = Reflect::get(value, &METADATA_KEY.into())
        .ok()
        .and_then(|m| m.as_string());
    let images: Vec<(&'static str, Vec<u8>)> = IMAGE_KEYS
        .iter()
        .filter_map(|&(key, _)| {
            let bytes = Reflect::get(value, &key.into())
                .ok()?
                .dyn_into::<Uint8Array>()
                .ok()?
                .to_vec();
            Some((key, bytes))
        })
        .collect();
    stored_pair::read_record(metadata.as_deref(), |key| {
        images
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, bytes)| bytes.as_slice())
    })
}

/// Loads every saved pair, sorted by id. Damaged records are skipped and reported.
pub async fn load_pairs() -> Result<(Vec<LabeledPair>, Vec<DamagedRecord>), StorageError> {
    let db = open().await?;
    let failed = StorageError::request("reading");
    let request = store(&db, IdbTransactionMode::Readonly)
        .and_then(|store| store.get_all())
        .map_err(&failed)?;
    let records: Array = settled(&request)
        .await
        .map_err(&failed)?
        .dyn_into()
        .map_err(|_| StorageError::Request {
            action: "reading",
            cause: JsError::missing("the stored pairs are not a list"),
        })?;
    let mut pairs = Vec::new();
    let mut damaged = Vec::new();
    for value in records.iter() {
        match read_record(&value) {
            Ok(pair) => pairs.push(pair),
            Err(e) => damaged.push(e),
        }
    }
    pairs.sort_by(|a, b| a.id.cmp(&b.id));
    Ok((pairs, damaged))
}

/// Fine-tuned weights the user kept, as stored.
#[derive(Debug, Clone)]
pub struct KeptWeights {
    /// The weights file's name.
    pub name: String,
    /// The weights file.
    pub bytes: Vec<u8>,
    /// Whether the page uses them (rather than the bundled weights) when it opens.
    pub chosen: bool,
}

/// The failure of a request to the store of weights (a full storage named as such).
fn model_request(action: &'static str) -> impl Fn(JsValue) -> StorageError {
    StorageError::failed(move |cause| StorageError::ModelRequest { action, cause })
}

/// Keeps `weights` as the fine-tuned weights (replacing any kept before, only once the write
/// has committed: a refused write leaves the previous ones).
pub async fn save_kept_weights(weights: &KeptWeights) -> Result<(), StorageError> {
    let failed = model_request("saving in");
    let record = Object::new();
    let set = |key: &str, value: &JsValue| Reflect::set(&record, &key.into(), value);
    set("name", &JsValue::from_str(&weights.name)).map_err(&failed)?;
    set("bytes", &Uint8Array::from(weights.bytes.as_slice())).map_err(&failed)?;
    set("chosen", &JsValue::from_bool(weights.chosen)).map_err(&failed)?;
    put_model_record(FINE_TUNED_KEY, Some(&record)).await
}

/// Puts `record` under `key` in the store of what the page reads pairs with, or deletes the
/// key's record (`None`); done once the transaction has committed.
async fn put_model_record(key: &str, record: Option<&JsValue>) -> Result<(), StorageError> {
    let db = open().await?;
    let failed = model_request("saving in");
    let transaction = db
        .transaction_with_str_and_mode(MODELS, IdbTransactionMode::Readwrite)
        .map_err(&failed)?;
    let store = transaction.object_store(MODELS).map_err(&failed)?;
    match record {
        Some(record) => store.put_with_key(record, &JsValue::from_str(key)),
        None => store.delete(&JsValue::from_str(key)),
    }
    .map_err(&failed)?;
    committed(&transaction).await.map_err(failed)
}

/// The record under `key` in the store of what the page reads pairs with, if any.
async fn model_record(key: &str) -> Result<Option<JsValue>, StorageError> {
    let db = open().await?;
    let failed = model_request("reading");
    let request = db
        .transaction_with_str_and_mode(MODELS, IdbTransactionMode::Readonly)
        .and_then(|t| t.object_store(MODELS))
        .and_then(|store| store.get(&JsValue::from_str(key)))
        .map_err(&failed)?;
    let record = settled(&request).await.map_err(&failed)?;
    Ok((!record.is_undefined() && !record.is_null()).then_some(record))
}

/// Keeps the catheter's calibration for the next visit (`None`: forgets it).
pub async fn save_calibration(
    calibration: Option<&StiffnessCalibration>,
) -> Result<(), StorageError> {
    let json = calibration
        .map(|c| serde_json::to_string(c).map(|json| JsValue::from_str(&json)))
        .transpose()
        .map_err(|e| StorageError::ModelRequest {
            action: "saving in",
            cause: JsError::missing(&format!("the calibration cannot be written: {e}")),
        })?;
    put_model_record(CALIBRATION_KEY, json.as_ref()).await
}

/// The catheter's calibration kept from an earlier visit, if any.
pub async fn load_calibration() -> Result<Option<StiffnessCalibration>, StorageError> {
    let Some(record) = model_record(CALIBRATION_KEY).await? else {
        return Ok(None);
    };
    let damaged = |why: String| StorageError::ModelRequest {
        action: "reading",
        cause: JsError::missing(&format!("the kept catheter calibration {why}")),
    };
    let json = record
        .as_string()
        .ok_or_else(|| damaged("is not text".into()))?;
    serde_json::from_str(&json)
        .map(Some)
        .map_err(|e| damaged(format!("cannot be read: {e}")))
}

/// The kept fine-tuned weights, if any.
pub async fn load_kept_weights() -> Result<Option<KeptWeights>, StorageError> {
    let Some(record) = model_record(FINE_TUNED_KEY).await? else {
        return Ok(None);
    };
    let get = |key: &str| Reflect::get(&record, &key.into()).unwrap_or_default();
    let damaged = |what: &str| StorageError::ModelRequest {
        action: "reading",
        cause: JsError::missing(&format!("the kept weights' {what}")),
    };
    let name = get("name").as_string().ok_or_else(|| damaged("name"))?;
    let bytes = get("bytes")
        .dyn_into::<Uint8Array>()
        .map_err(|_| damaged("file"))?
        .to_vec();
    Ok(Some(KeptWeights {
        name,
        bytes,
        chosen: get("chosen").as_bool().unwrap_or(false),
    }))
}
