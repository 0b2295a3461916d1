//! Fine-tuning H-Net in the page, in a dedicated Web Worker (`www/module-worker.js?module=hnet-tune`),
//! so that the page keeps answering while it trains. The training itself is
//! [`hnet_model::fine_tune`]'s, on Burn's CPU backend with the project's kernels (WebAssembly
//! SIMD), or on WebGPU in the WebGPU worker (crates/hnet-gpu links these exports and trains on
//! its device: [`train_on`]). The page (src/studio/tuning.rs) drives it with messages, each
//! calling one export; every read-back is asynchronous, as WebGPU requires:
//!
//! 1. [`start_tuning`] takes the weights file, the labelled pairs and the settings, splits the
//!    pairs into trained-on and held-back ones, and scores the starting network on the held-back
//!    ones;
//! 2. each training step is split between the page's tuning workers, one per core on the CPU
//!    and one on WebGPU, whose share is the whole step ([`hnet_model::fine_tune::Share`]):
//!    [`share`] computes this worker's share of the step's
//!    gradients, and [`apply`] applies the average of every worker's share, which the page
//!    relays to each; at the end of an epoch the first worker scores the held-back pairs again,
//!    and the worker given the reference pairs (the last) scores those, at the same time.
//!    The page calls them until the run has finished (or stops the workers);
//! 3. [`best_weights`] writes the best epoch's network as a weights file (the first worker's).
//!
//! One fine-tune per worker: the page starts fresh workers for each run and stops them by
//! terminating them, which leaves every weights file the page holds as it was.
#![cfg(target_arch = "wasm32")]

use std::cell::RefCell;
use std::collections::BTreeMap;

use burn::tensor::Device;
use hnet_model::fine_tune::{FineTune, FineTuneSettings, Share, TrainingPair};
use hnet_units::{ImageSize, TipForce, with_causes};
use wasm_bindgen::prelude::*;

thread_local! {
    /// The run [`start_tuning`] began (taken out while a call awaits the device).
    static RUN: RefCell<Option<FineTune>> = const { RefCell::new(None) };
    /// The device trained on: the CPU unless [`train_on`] said otherwise.
    static DEVICE: RefCell<Option<Device>> = const { RefCell::new(None) };
}

/// Trains this worker's next fine-tune on `device` (the WebGPU worker's, once set up) instead
/// of the CPU.
pub fn train_on(device: Device) {
    DEVICE.set(Some(device));
}

/// The JavaScript error the page receives: the message with its causes.
fn js_error(error: &dyn std::error::Error) -> JsError {
    JsError::new(&with_causes(error))
}

fn json<T: serde::Serialize>(value: &T) -> Result<String, JsError> {
    serde_json::to_string(value).map_err(|e| js_error(&e))
}

/// Starts a fine-tune of the weights file `weights` (`name` names it in errors) on the pairs in
/// `images` and `forces`, scoring the reference pairs in `reference_images` and
/// `reference_forces` after every epoch without training on them, and training on the pairs in
/// `rehearsal_images` and `rehearsal_forces` without holding any back, with the settings in
/// `settings_json` ([`FineTuneSettings`]; fields left out keep their defaults; `replicas` is the
/// number of tuning workers the page runs). A `follower` (every worker but the first) only
/// trains, and scores the reference pairs if it was given some.
///
/// `images` holds each pair in turn at `width`×`height` pixels (row-major, `height` rows of
/// `width` pixels): view A and view B as 8-bit RGB, then mask A and mask B (255 catheter).
/// `forces` holds each pair's force label `(Fx, Fy, Fz)` in newtons, NaN for a pair that trains
/// its masks only.
///
/// Returns, as JSON, the split (`train`, `held_back`), `steps_per_epoch` and the starting
/// network's scores on the held-back pairs (`before`) and the reference pairs
/// (`before_reference`, `null` without any); `before` is `null` for a follower.
#[wasm_bindgen]
#[allow(clippy::too_many_arguments)]
pub async fn start_tuning(
    weights: Vec<u8>,
    name: String,
    width: u32,
    height: u32,
    images: Vec<u8>,
    forces: Vec<f32>,
    reference_images: Vec<u8>,
    reference_forces: Vec<f32>,
    rehearsal_images: Vec<u8>,
    rehearsal_forces: Vec<f32>,
    settings_json: String,
    follower: bool,
) -> Result<String, JsError> {
    console_error_panic_hook::set_once();
    let settings: FineTuneSettings = serde_json::from_str(&settings_json)
        .map_err(|e| JsError::new(&format!("the fine-tune settings are not readable: {e}")))?;
    let size = ImageSize::new(width as usize, height as usize);
    let pairs = unpack(size, &images, &forces, "pairs")?;
    let reference = unpack(
        size,
        &reference_images,
        &reference_forces,
        "reference pairs",
    )?;
    let rehearsal = unpack(
        size,
        &rehearsal_images,
        &rehearsal_forces,
        "rehearsed pairs",
    )?;
    let device = DEVICE
        .with_borrow(Clone::clone)
        .unwrap_or_else(Device::flex);
    let run = FineTune::new(&weights, &name, pairs, settings, &device)
        .and_then(|run| run.with_reference(reference))
        .and_then(|run| run.with_rehearsal(rehearsal))
        .map(|run| if follower { run.as_follower() } else { run })
        .map_err(|e| js_error(&e))?;
    let before = if follower {
        None
    } else {
        Some(run.score_async().await.map_err(|e| js_error(&e))?)
    };
    let before_reference = run
        .score_reference_async()
        .await
        .map_err(|e| js_error(&e))?;
    let (train, held_back) = run.split();
    let reply = serde_json::json!({
        "train": train,
        "held_back": held_back,
        "steps_per_epoch": run.steps_per_epoch(),
        "before": before,
        "before_reference": before_reference,
    });
    RUN.set(Some(run));
    json(&reply)
}

/// The pairs packed in `images` and `forces` ([`start_tuning`]'s layout); `what` names them in errors.
fn unpack(
    size: ImageSize,
    images: &[u8],
    forces: &[f32],
    what: &str,
) -> Result<Vec<TrainingPair>, JsError> {
    let (rgb, grey) = (size.pixels() * 3, size.pixels());
    let per_pair = 2 * rgb + 2 * grey;
    if per_pair == 0
        || !images.len().is_multiple_of(per_pair)
        || images.len() / per_pair * 3 != forces.len()
    {
        return Err(JsError::new(&format!(
            "the {what} sent are not whole {size} pairs: {} image bytes, {} force values",
            images.len(),
            forces.len()
        )));
    }
    Ok(images
        .chunks_exact(per_pair)
        .zip(forces.chunks_exact(3))
        .map(|(bytes, force)| {
            let (view_a, rest) = bytes.split_at(rgb);
            let (view_b, rest) = rest.split_at(rgb);
            let (mask_a, mask_b) = rest.split_at(grey);
            TrainingPair {
                view_a: view_a.to_vec(),
                view_b: view_b.to_vec(),
                mask_a: mask_a.to_vec(),
                mask_b: mask_b.to_vec(),
                force_n: Some(TipForce::new(force[0], force[1], force[2]))
                    .filter(|f| f.is_finite()),
            }
        })
        .collect())
}

/// This worker's share of the next training step, replica `replica` of the settings'
/// `replicas`, as [`Share::to_message`] writes it.
#[wasm_bindgen]
pub async fn share(replica: u32) -> Result<Vec<f32>, JsError> {
    with_run(async |run| {
        run.share_async(replica as usize)
            .await
            .map(|share| share.to_message())
            .map_err(|e| js_error(&e))
    })
    .await
}

/// Applies the step whose shares are `messages` (every worker's [`share`], in replica order,
/// one after another). Returns, as JSON, `report`: the epoch's report when the step ended an
/// epoch on the first worker ([`hnet_model::fine_tune::EpochReport`]), or `null`; and
/// `reference`: a follower's scores on its reference pairs when the step ended an epoch and it
/// holds some, or `null`.
#[wasm_bindgen]
pub async fn apply(messages: Vec<f32>) -> Result<String, JsError> {
    with_run(async |run| {
        let shares = Share::from_messages(&messages).map_err(|e| js_error(&e))?;
        let epochs = run.epochs_done();
        let report = run.apply_async(&shares).await.map_err(|e| js_error(&e))?;
        let reference = if report.is_none() && run.epochs_done() > epochs {
            run.score_reference_async()
                .await
                .map_err(|e| js_error(&e))?
        } else {
            None
        };
        json(&serde_json::json!({ "report": report, "reference": reference }))
    })
    .await
}

/// `f` on the run [`start_tuning`] began, taken out of [`RUN`] while `f` awaits the device (the
/// page sends a worker one call at a time) and put back after.
async fn with_run<T>(
    f: impl AsyncFnOnce(&mut FineTune) -> Result<T, JsError>,
) -> Result<T, JsError> {
    let mut run = RUN.take().ok_or_else(|| {
        JsError::new(
            "no fine-tune has been started in this worker, or a call to it is still running",
        )
    })?;
    let result = f(&mut run).await;
    RUN.set(Some(run));
    result
}

/// The best epoch's network as a weights file whose provenance is `provenance_json` (an object
/// of strings); empty when no epoch improved on the held-back pairs.
#[wasm_bindgen]
pub fn best_weights(provenance_json: &str) -> Result<Vec<u8>, JsError> {
    let provenance: BTreeMap<String, String> = serde_json::from_str(provenance_json)
        .map_err(|e| JsError::new(&format!("the provenance is not readable: {e}")))?;
    RUN.with_borrow(|run| {
        let run = run
            .as_ref()
            .ok_or_else(|| JsError::new("no fine-tune has been started in this worker"))?;
        Ok(run
            .best_weights(&provenance)
            .map_err(|e| js_error(&e))?
            .unwrap_or_default())
    })
}
