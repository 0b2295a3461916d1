//! Fine-tuning H-Net in the page, in a dedicated Web Worker (`www/module-worker.js?module=hnet-tune`),
//! so that the page keeps answering while it trains. The training itself is
//! [`hnet_model::fine_tune`]'s, on Burn's CPU backend with the project's kernels (WebAssembly
//! SIMD). The page (src/fine_tune.rs) drives it with messages, each calling one export:
//!
//! 1. [`start`] takes the weights file, the labelled pairs and the settings, splits the pairs
//!    into trained-on and held-back ones, and scores the starting network on the held-back ones;
//! 2. each training step is split between the page's tuning workers, one per core
//!    ([`hnet_model::fine_tune::Share`]): [`share`] computes this worker's share of the step's
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
    /// The run [`start`] began.
    static RUN: RefCell<Option<FineTune>> = const { RefCell::new(None) };
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
pub fn start(
    weights: &[u8],
    name: &str,
    width: u32,
    height: u32,
    images: &[u8],
    forces: &[f32],
    reference_images: &[u8],
    reference_forces: &[f32],
    rehearsal_images: &[u8],
    rehearsal_forces: &[f32],
    settings_json: &str,
    follower: bool,
) -> Result<String, JsError> {
    console_error_panic_hook::set_once();
    let settings: FineTuneSettings = serde_json::from_str(settings_json)
        .map_err(|e| JsError::new(&format!("the fine-tune settings are not readable: {e}")))?;
    let size = ImageSize::new(width as usize, height as usize);
    let pairs = unpack(size, images, forces, "pairs")?;
    let reference = unpack(size, reference_images, reference_forces, "reference pairs")?;
    let rehearsal = unpack(size, rehearsal_images, rehearsal_forces, "rehearsed pairs")?;
    let run = FineTune::new(weights, name, pairs, settings, &Device::flex())
        .and_then(|run| run.with_reference(reference))
        .and_then(|run| run.with_rehearsal(rehearsal))
        .map(|run| if follower { run.as_follower() } else { run })
        .map_err(|e| js_error(&e))?;
    let before = if follower {
        None
    } else {
        Some(run.score().map_err(|e| js_error(&e))?)
    };
    let before_reference = run.score_reference().map_err(|e| js_error(&e))?;
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

/// The pairs packed in `images` and `forces` ([`start`]'s layout); `what` names them in errors.
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
pub fn share(replica: u32) -> Result<Vec<f32>, JsError> {
    with_run(|run| {
        run.share(replica as usize)
            .map(|share| share.to_message())
            .map_err(|e| js_error(&e))
    })
}

/// Applies the step whose shares are `messages` (every worker's [`share`], in replica order,
/// one after another). Returns, as JSON, `report`: the epoch's report when the step ended an
/// epoch on the first worker ([`hnet_model::fine_tune::EpochReport`]), or `null`; and
/// `reference`: a follower's scores on its reference pairs when the step ended an epoch and it
/// holds some, or `null`.
#[wasm_bindgen]
pub fn apply(messages: &[f32]) -> Result<String, JsError> {
    with_run(|run| {
        let shares = Share::from_messages(messages).map_err(|e| js_error(&e))?;
        let epochs = run.epochs_done();
        let report = run.apply(&shares).map_err(|e| js_error(&e))?;
        let reference = if report.is_none() && run.epochs_done() > epochs {
            run.score_reference().map_err(|e| js_error(&e))?
        } else {
            None
        };
        json(&serde_json::json!({ "report": report, "reference": reference }))
    })
}

/// `f` on the run [`start`] began.
fn with_run<T>(f: impl FnOnce(&mut FineTune) -> Result<T, JsError>) -> Result<T, JsError> {
    RUN.with_borrow_mut(|run| {
        f(run
            .as_mut()
            .ok_or_else(|| JsError::new("no fine-tune has been started in this worker"))?)
    })
}

/// The best epoch's network as a weights file whose provenance is `provenance_json` (an object
/// of strings); empty when no epoch improved on the held-back pairs.
#[wasm_bindgen]
pub fn best_weights(provenance_json: &str) -> Result<Vec<u8>, JsError> {
    let provenance: BTreeMap<String, String> = serde_json::from_str(provenance_json)
        .map_err(|e| JsError::new(&format!("the provenance is not readable: {e}")))?;
    with_run(|run| {
        Ok(run
            .best_weights(&provenance)
            .map_err(|e| js_error(&e))?
            .unwrap_or_default())
    })
}
