//! H-Net on WebGPU for the page, run in a dedicated Web Worker (`www/module-worker.js?module=hnet-gpu`).
//!
//! The WebGPU stack (Burn's wgpu backend: wgpu, cubecl) is about two thirds of the code the page
//! would otherwise download (docs/benchmarks.md, "The page's download"). The page keeps only
//! the CPU backend and fetches this module when it decides to use WebGPU: on a hardware adapter,
//! or when the user asks for WebGPU. The page (src/gpu_worker.rs) talks to the worker with
//! messages; each calls one of the exports below:
//!
//! 1. [`start`] sets WebGPU up in the worker;
//! 2. [`load`] takes a weights file (the page has already read it on the CPU) and names the
//!    network it loaded by a handle;
//! 3. [`infer`] runs that network on one stereo pair and returns the prediction packed
//!    ([`StereoPrediction::to_packed`](hnet_model::inference::StereoPrediction::to_packed));
//! 4. [`unload`] frees it when the page no longer uses it.
//!
//! The same module fine-tunes on WebGPU: it carries the fine-tuning worker's exports
//! (crates/hnet-tune: `start_tuning`, `share`, `apply`, `best_weights`), and [`start`] makes them
//! train on its device. The page starts a worker of its own for a fine-tune, as on the CPU.
//!
//! The page checks WebGPU's result against its CPU's on a check pair before trusting it
//! (src/webgpu_check.rs), and falls back to the CPU whenever the worker fails.
#![cfg(target_arch = "wasm32")]

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::rc::Rc;

use burn::tensor::Device;
use hnet_model::HNet;
use hnet_model::inference::StereoPair;
use hnet_units::mask::MaskAveraging;
use hnet_units::{ImageSize, with_causes};
use js_sys::Float32Array;
use wasm_bindgen::prelude::*;

/// A network loaded in the worker, with its input size and how it reads each view.
struct Loaded {
    model: HNet,
    input: ImageSize,
    averaging: MaskAveraging,
}

thread_local! {
    /// The WebGPU device, once set up: wgpu registers one runtime per device and worker.
    static DEVICE: RefCell<Option<Device>> = const { RefCell::new(None) };
    /// The networks [`load`] loaded and [`unload`] has not freed, by handle.
    static LOADED: RefCell<HashMap<u32, Rc<Loaded>>> = RefCell::new(HashMap::new());
    /// The next network's handle.
    static NEXT_HANDLE: Cell<u32> = const { Cell::new(1) };
}

/// The JavaScript error the page receives: the message with its causes.
fn js_error(error: &dyn std::error::Error) -> JsError {
    JsError::new(&with_causes(error))
}

/// The device set up by [`start`].
fn device() -> Result<Device, JsError> {
    DEVICE
        .with_borrow(Clone::clone)
        .ok_or_else(|| JsError::new("WebGPU is not set up in the worker"))
}

/// Sets WebGPU up in this worker, on the adapter the browser offers (once; later calls reuse the
/// device). Fails with wgpu's own account when there is no adapter or device.
#[wasm_bindgen]
pub async fn start() -> Result<(), JsError> {
    // A panic's message goes to the worker's console (the page then falls back to the CPU).
    console_error_panic_hook::set_once();
    if DEVICE.with_borrow(Option::is_some) {
        return Ok(());
    }
    let device = Device::wgpu_options()
        .init_async()
        .await
        .map_err(|e| js_error(&e))?;
    hnet_tune::train_on(device.clone());
    DEVICE.set(Some(device));
    Ok(())
}

/// Loads H-Net from a weights file's bytes (`name` names it in errors) onto WebGPU, to read each
/// view as `mask_averaging` names ([`MaskAveraging::name`]: how the weights' calibration was
/// measured). Returns the network's handle for [`infer`] and [`unload`].
#[wasm_bindgen]
pub fn load(weights: &[u8], name: &str, mask_averaging: &str) -> Result<u32, JsError> {
    let averaging = MaskAveraging::from_name(mask_averaging).map_err(|e| js_error(&e))?;
    let (model, config, _) =
        HNet::from_weights_bytes(weights, &device()?, name).map_err(|e| js_error(&e))?;
    let input = config.image_size;
    let handle = NEXT_HANDLE.get();
    NEXT_HANDLE.set(handle.wrapping_add(1));
    LOADED.with_borrow_mut(|loaded| {
        loaded.insert(
            handle,
            Rc::new(Loaded {
                model,
                input,
                averaging,
            }),
        )
    });
    Ok(handle)
}

/// Frees the network of `handle` (an unknown handle is ignored).
#[wasm_bindgen]
pub fn unload(handle: u32) {
    LOADED.with_borrow_mut(|loaded| loaded.remove(&handle));
}

/// Runs the network of `handle` on one stereo pair: two 8-bit RGB images, row-major, at its
/// input size, each view read as the network was loaded to. Returns view A's and view B's catheter probabilities and the tip force in
/// newtons, packed ([`hnet_model::inference::StereoPrediction::to_packed`]).
#[wasm_bindgen]
pub async fn infer(handle: u32, view_a: Vec<u8>, view_b: Vec<u8>) -> Result<Float32Array, JsError> {
    let loaded = LOADED
        .with_borrow(|loaded| loaded.get(&handle).cloned())
        .ok_or_else(|| JsError::new(&format!("the WebGPU worker holds no network {handle}")))?;
    let device = device()?;
    let pair = StereoPair {
        view_a: &view_a,
        view_b: &view_b,
    };
    let prediction = loaded
        .model
        .predict_async(&[pair], loaded.input, &device, loaded.averaging)
        .await
        .map_err(|e| js_error(&e))?
        .into_iter()
        .next()
        .ok_or_else(|| JsError::new("H-Net returned no prediction"))?;
    Ok(Float32Array::from(&prediction.to_packed()[..]))
}
