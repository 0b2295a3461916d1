//! H-Net on the CPU for the page, run in a pool of dedicated Web Workers
//! (`www/module-worker.js?module=hnet-cpu`), one per core the browser reports.
//!
//! A worker reads one view at a time: its segmentation branch, giving the view's mask and the
//! pooled features the force head takes ([`hnet_model::inference::ViewReading`]). The page
//! (src/cpu_pool.rs) hands a pair's two views to two workers at once and a cine's frames to all
//! of them, then joins each pair's views with the force head on its own thread
//! ([`hnet_model::HNet::join_views`], a few thousand multiply-adds). The exports:
//!
//! 1. [`start`] installs the panic hook;
//! 2. [`load`] takes a weights file (the page has already read it) and names the network it
//!    loaded by a handle;
//! 3. [`read_view`] runs that network's branch of one view on one image and returns the reading
//!    packed ([`ViewReading::to_packed`](hnet_model::inference::ViewReading::to_packed));
//! 4. [`unload`] frees it.
#![cfg(target_arch = "wasm32")]

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::rc::Rc;

use burn::tensor::Device;
use hnet_model::HNet;
use hnet_units::mask::MaskAveraging;
use hnet_units::{ImageSize, View, with_causes};
use js_sys::Float32Array;
use wasm_bindgen::prelude::*;

/// A network loaded in the worker, with its input size and how it reads each view.
struct Loaded {
    model: HNet,
    input: ImageSize,
    averaging: MaskAveraging,
}

thread_local! {
    /// The networks [`load`] loaded and [`unload`] has not freed, by handle.
    static LOADED: RefCell<HashMap<u32, Rc<Loaded>>> = RefCell::new(HashMap::new());
    /// The next network's handle.
    static NEXT_HANDLE: Cell<u32> = const { Cell::new(1) };
}

/// The JavaScript error the page receives: the message with its causes.
fn js_error(error: &dyn std::error::Error) -> JsError {
    JsError::new(&with_causes(error))
}

/// Installs the panic hook: a panic's message goes to the worker's console (the page then
/// replaces the worker). `large_winograd_tiles` false keeps the convolutions on Winograd's
/// F(2x2, 3x3) tiles (the page's `?winograd-tiles=2`, for A/B timings).
#[wasm_bindgen]
pub fn start(large_winograd_tiles: bool) {
    console_error_panic_hook::set_once();
    hnet_conv::use_large_winograd_tiles(large_winograd_tiles);
}

/// Loads H-Net from a weights file's bytes (`name` names it in errors), to read each view as
/// `mask_averaging` names ([`MaskAveraging::name`]: how the weights' calibration was measured).
/// Returns the network's handle for [`read_view`] and [`unload`].
#[wasm_bindgen]
pub fn load(weights: &[u8], name: &str, mask_averaging: &str) -> Result<u32, JsError> {
    let averaging = MaskAveraging::from_name(mask_averaging).map_err(|e| js_error(&e))?;
    let (model, config, _) =
        HNet::from_weights_bytes(weights, &Device::flex(), name).map_err(|e| js_error(&e))?;
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

/// Runs the branch of view `view` (0: A, 1: B) of the network of `handle` on one 8-bit RGB
/// image, row-major, at its input size, as the network was loaded to read views. Returns the
/// view's catheter probabilities and pooled features, packed ([`hnet_model::inference::ViewReading::to_packed`]).
#[wasm_bindgen]
pub fn read_view(handle: u32, view: u32, image: Vec<u8>) -> Result<Float32Array, JsError> {
    let loaded = LOADED
        .with_borrow(|loaded| loaded.get(&handle).cloned())
        .ok_or_else(|| JsError::new(&format!("the CPU worker holds no network {handle}")))?;
    let view = match view {
        0 => View::A,
        1 => View::B,
        other => {
            return Err(JsError::new(&format!(
                "a pair has views 0 and 1, not {other}"
            )));
        }
    };
    let reading = loaded
        .model
        .read_view(
            view,
            &image,
            loaded.input,
            &Device::flex(),
            loaded.averaging,
        )
        .map_err(|e| js_error(&e))?;
    Ok(Float32Array::from(&reading.to_packed()[..]))
}
