//! The page's side of the WebGPU worker (crates/hnet-gpu in a [`ModuleWorker`]): H-Net on
//! WebGPU, in a module the page fetches only when it uses WebGPU. A worker that fails is
//! dropped, and the next use of WebGPU starts a fresh one.

use std::cell::RefCell;
use std::rc::Rc;

use hnet_model::inference::StereoPrediction;
use hnet_units::ImageSize;
use hnet_units::mask::MaskAveraging;
use js_sys::{Array, Float32Array, Promise, Uint8Array};
use wasm_bindgen::prelude::*;

use crate::browser::JsError;
use crate::module_worker::{ModuleWorker, ModuleWorkerError, within};

/// How long the worker may take to start: to fetch and compile its module (2.4 MB gzipped,
/// docs/benchmarks.md) and set WebGPU up, seconds. A browser whose WebGPU never answers would
/// otherwise leave the page loading for ever; then the page uses the CPU.
pub const START_TIMEOUT_S: i32 = 120;

/// Why the WebGPU worker gave no answer.
#[derive(Debug, thiserror::Error)]
pub enum GpuWorkerError {
    /// The worker could not be started, stopped, or a call failed.
    #[error(transparent)]
    Worker(#[from] ModuleWorkerError),
    /// The worker answered with something else than the prediction asked for.
    #[error("the WebGPU worker returned {found} values, not a prediction for {size} images")]
    NotAPrediction {
        /// Values returned.
        found: usize,
        /// The network's input size.
        size: ImageSize,
    },
}

/// A running WebGPU worker with WebGPU set up in it.
pub struct GpuWorker {
    worker: ModuleWorker,
}

/// The worker, in words.
const NAME: &str = "the WebGPU worker";

thread_local! {
    /// The page's worker and the reply to its `start` call (awaited by every caller, so that
    /// loads asked for while it starts share it): one WebGPU device per page, reused when the
    /// user switches back to WebGPU or loads other weights.
    static SHARED: RefCell<Option<(Rc<GpuWorker>, Promise)>> = const { RefCell::new(None) };
}

impl GpuWorker {
    /// The page's worker, started (and WebGPU set up in it) on first use, and again after it
    /// stopped.
    pub async fn shared() -> Result<Rc<Self>, GpuWorkerError> {
        let running = SHARED
            .with_borrow(Clone::clone)
            .filter(|(worker, _)| worker.worker.stopped().is_none());
        let (worker, started) = match running {
            Some(running) => running,
            None => {
                let worker = Rc::new(Self {
                    worker: ModuleWorker::spawn("hnet-gpu", NAME)?,
                });
                let started = within(
                    worker.worker.send("start", &Array::new(), &Array::new())?,
                    START_TIMEOUT_S,
                    &format!("it did not start within {START_TIMEOUT_S} s"),
                );
                SHARED.set(Some((worker.clone(), started.clone())));
                (worker, started)
            }
        };
        if let Err(e) = worker.worker.reply("start", started).await {
            worker.discard(&hnet_units::with_causes(&e));
            return Err(e.into());
        }
        Ok(worker)
    }

    /// Stops the worker after a failure: its calls fail from now on, and the next use of WebGPU
    /// starts a fresh worker.
    pub fn discard(&self, why: &str) {
        self.worker.stop(why);
        SHARED.with_borrow_mut(|shared| {
            if shared
                .as_ref()
                .is_some_and(|(w, _)| std::ptr::eq(Rc::as_ptr(w), self))
            {
                *shared = None;
            }
        });
    }

    /// Calls the worker; a failed call stops it for good.
    async fn call(
        &self,
        call: &'static str,
        args: &Array,
        transfer: &Array,
    ) -> Result<JsValue, GpuWorkerError> {
        let result = self.worker.call(call, args, transfer).await;
        if let Err(e) = &result {
            self.discard(&hnet_units::with_causes(e));
        }
        Ok(result?)
    }

    /// Loads a weights file (`name` names it in errors) onto WebGPU, to read each view as
    /// `averaging` says; the network lives in the worker until the returned handle is dropped.
    pub async fn load(
        self: &Rc<Self>,
        weights: &[u8],
        name: &str,
        averaging: MaskAveraging,
    ) -> Result<GpuNetwork, GpuWorkerError> {
        let bytes = Uint8Array::from(weights);
        let args = Array::of3(
            &bytes,
            &JsValue::from_str(name),
            &JsValue::from_str(averaging.name()),
        );
        let handle = self
            .call("load", &args, &Array::of1(&bytes.buffer()))
            .await?
            .as_f64()
            .ok_or_else(|| ModuleWorkerError::Call {
                worker: NAME,
                call: "load",
                cause: JsError::missing("the network's handle"),
            })?;
        Ok(GpuNetwork {
            worker: self.clone(),
            handle: handle as u32,
        })
    }
}

/// A network loaded in the WebGPU worker; dropping it frees it there.
pub struct GpuNetwork {
    worker: Rc<GpuWorker>,
    handle: u32,
}

impl GpuNetwork {
    /// Runs the network on one stereo pair of RGB images of `size`, its input size.
    pub async fn infer(
        &self,
        view_a: &[u8],
        view_b: &[u8],
        size: ImageSize,
    ) -> Result<StereoPrediction, GpuWorkerError> {
        let (a, b) = (Uint8Array::from(view_a), Uint8Array::from(view_b));
        let args = Array::of3(&JsValue::from(self.handle), &a, &b);
        let values = self
            .worker
            .call("infer", &args, &Array::of2(&a.buffer(), &b.buffer()))
            .await?
            .dyn_into::<Float32Array>()
            .map_err(|_| GpuWorkerError::NotAPrediction { found: 0, size })?
            .to_vec();
        StereoPrediction::from_packed(&values, size).ok_or(GpuWorkerError::NotAPrediction {
            found: values.len(),
            size,
        })
    }
}

impl Drop for GpuNetwork {
    fn drop(&mut self) {
        // Nothing waits for the reply; a stopped worker holds nothing.
        let args = Array::of1(&JsValue::from(self.handle));
        self.worker.worker.post("unload", &args);
    }
}
