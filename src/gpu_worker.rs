//! The page's side of the WebGPU worker (`www/gpu-worker.js`, running crates/hnet-gpu): H-Net
//! on WebGPU, in a module the page fetches only when it uses WebGPU. Each call becomes a
//! message and its reply a Rust result; a worker that fails is dropped, and the next use of
//! WebGPU starts a fresh one.

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::rc::Rc;

use hnet_model::inference::StereoPrediction;
use hnet_units::ImageSize;
use js_sys::{Array, Float32Array, Function, Object, Promise, Reflect, Uint8Array};
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{Event, MessageEvent, Worker, WorkerOptions, WorkerType};

use crate::browser::JsError;

/// The worker's script, next to the page (trunk copies it; index.html).
pub const WORKER_SCRIPT: &str = "gpu-worker.js";

/// How long the worker may take to start: to fetch and compile its module (2.4 MB gzipped,
/// docs/benchmarks.md) and set WebGPU up, seconds. A browser whose WebGPU never answers would
/// otherwise leave the page loading for ever; then the page uses the CPU.
pub const START_TIMEOUT_S: i32 = 120;

/// Why the WebGPU worker gave no answer.
#[derive(Debug, thiserror::Error)]
pub enum GpuWorkerError {
    /// The browser would not start the worker.
    #[error("the WebGPU worker cannot be started")]
    Spawn(#[source] JsError),
    /// The worker stopped (its script or module could not be loaded, or it crashed).
    #[error("the WebGPU worker stopped ({0})")]
    Stopped(String),
    /// A call failed in the worker (the cause is the worker's own account).
    #[error("the WebGPU worker's `{call}` failed")]
    Call {
        /// The worker function called.
        call: &'static str,
        /// What the worker said.
        #[source]
        cause: JsError,
    },
    /// The worker answered with something else than the prediction asked for.
    #[error("the WebGPU worker returned {found} values, not a prediction for {size} images")]
    NotAPrediction {
        /// Values returned.
        found: usize,
        /// The network's input size.
        size: ImageSize,
    },
}

/// The `resolve` and `reject` functions of a call waiting for its reply.
type Pending = HashMap<u32, (Function, Function)>;

/// A running WebGPU worker with WebGPU set up in it.
pub struct GpuWorker {
    worker: Worker,
    pending: Rc<RefCell<Pending>>,
    /// Why the worker stopped, once it has.
    stopped: Rc<RefCell<Option<String>>>,
    next_id: Cell<u32>,
    _on_message: Closure<dyn FnMut(MessageEvent)>,
    _on_error: Closure<dyn FnMut(Event)>,
}

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
            .filter(|(worker, _)| worker.stopped.borrow().is_none());
        let (worker, started) = match running {
            Some(running) => running,
            None => {
                let worker = Rc::new(Self::spawn()?);
                let started =
                    within_start_time(worker.send("start", &Array::new(), &Array::new())?);
                SHARED.set(Some((worker.clone(), started.clone())));
                (worker, started)
            }
        };
        if let Err(e) = worker.reply("start", started).await {
            worker.discard(&hnet_units::with_causes(&e));
            return Err(e);
        }
        Ok(worker)
    }

    /// Stops the worker after a failure: its calls fail from now on, and the next use of WebGPU
    /// starts a fresh worker.
    pub fn discard(&self, why: &str) {
        self.worker.terminate();
        stop(&self.pending, &self.stopped, why);
        SHARED.with_borrow_mut(|shared| {
            if shared
                .as_ref()
                .is_some_and(|(w, _)| std::ptr::eq(Rc::as_ptr(w), self))
            {
                *shared = None;
            }
        });
    }

    /// Starts the worker script as a module worker, listening for its replies.
    fn spawn() -> Result<Self, GpuWorkerError> {
        let options = WorkerOptions::new();
        options.set_type(WorkerType::Module);
        options.set_name("hnet-gpu");
        let worker = Worker::new_with_options(WORKER_SCRIPT, &options)
            .map_err(|e| GpuWorkerError::Spawn(e.into()))?;
        let pending: Rc<RefCell<Pending>> = Rc::default();
        let stopped: Rc<RefCell<Option<String>>> = Rc::default();
        let on_message = {
            let pending = pending.clone();
            Closure::<dyn FnMut(MessageEvent)>::new(move |event: MessageEvent| {
                let data = event.data();
                let field = |key: &str| Reflect::get(&data, &JsValue::from_str(key)).ok();
                let Some(id) = field("id").and_then(|id| id.as_f64()) else {
                    return;
                };
                let Some((resolve, reject)) = pending.borrow_mut().remove(&(id as u32)) else {
                    return;
                };
                match field("error").filter(|e| !e.is_undefined()) {
                    Some(error) => reject.call1(
                        &JsValue::NULL,
                        &js_sys::Error::new(
                            &error.as_string().unwrap_or_else(|| format!("{error:?}")),
                        ),
                    ),
                    None => resolve.call1(&JsValue::NULL, &field("value").unwrap_or_default()),
                }
                .ok();
            })
        };
        // The script or its module could not be loaded, or the worker crashed: every waiting
        // call fails with why, and so does every later one.
        let on_error = {
            let (pending, stopped) = (pending.clone(), stopped.clone());
            Closure::<dyn FnMut(Event)>::new(move |event: Event| {
                event.prevent_default();
                let message = Reflect::get(&event, &JsValue::from_str("message"))
                    .ok()
                    .and_then(|m| m.as_string())
                    .filter(|m| !m.is_empty())
                    .unwrap_or_else(|| format!("{WORKER_SCRIPT} could not be run"));
                stop(&pending, &stopped, &message);
            })
        };
        worker.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
        worker.set_onerror(Some(on_error.as_ref().unchecked_ref()));
        Ok(Self {
            worker,
            pending,
            stopped,
            next_id: Cell::new(0),
            _on_message: on_message,
            _on_error: on_error,
        })
    }

    /// Sends the worker a call of `call` with `args`, handing over the buffers in `transfer`;
    /// the promise settles with its reply.
    fn send(
        &self,
        call: &'static str,
        args: &Array,
        transfer: &Array,
    ) -> Result<Promise, GpuWorkerError> {
        if let Some(why) = self.stopped.borrow().clone() {
            return Err(GpuWorkerError::Stopped(why));
        }
        let id = self.next_id.get();
        self.next_id.set(id.wrapping_add(1) % UNANSWERED);
        let pending = self.pending.clone();
        let reply = Promise::new(&mut |resolve, reject| {
            pending.borrow_mut().insert(id, (resolve, reject));
        });
        if let Err(e) = self
            .worker
            .post_message_with_transfer(&message(id, call, args), transfer)
        {
            self.pending.borrow_mut().remove(&id);
            return Err(GpuWorkerError::Call {
                call,
                cause: e.into(),
            });
        }
        Ok(reply)
    }

    /// The reply to a call of `call`.
    async fn reply(&self, call: &'static str, reply: Promise) -> Result<JsValue, GpuWorkerError> {
        JsFuture::from(reply).await.map_err(|e| {
            let cause = JsError::from(e);
            match self.stopped.borrow().clone() {
                Some(why) => GpuWorkerError::Stopped(why),
                None => GpuWorkerError::Call { call, cause },
            }
        })
    }

    /// Calls the worker's `call` with `args`, handing over the buffers in `transfer`. A failed
    /// call stops the worker: a module that trapped (a panic aborts it) cannot be trusted again.
    async fn call(
        &self,
        call: &'static str,
        args: &Array,
        transfer: &Array,
    ) -> Result<JsValue, GpuWorkerError> {
        let reply = self.send(call, args, transfer)?;
        let result = self.reply(call, reply).await;
        if let Err(e) = &result {
            self.discard(&hnet_units::with_causes(e));
        }
        result
    }

    /// Loads a weights file (`name` names it in errors) onto WebGPU; the network lives in the
    /// worker until the returned handle is dropped.
    pub async fn load(
        self: &Rc<Self>,
        weights: &[u8],
        name: &str,
    ) -> Result<GpuNetwork, GpuWorkerError> {
        let bytes = Uint8Array::from(weights);
        let args = Array::of2(&bytes, &JsValue::from_str(name));
        let handle = self
            .call("load", &args, &Array::of1(&bytes.buffer()))
            .await?
            .as_f64()
            .ok_or_else(|| GpuWorkerError::Call {
                call: "load",
                cause: JsError::missing("the network's handle"),
            })?;
        Ok(GpuNetwork {
            worker: self.clone(),
            handle: handle as u32,
        })
    }
}

impl Drop for GpuWorker {
    /// The last user of a worker stops it; its replies find no handler any more.
    fn drop(&mut self) {
        self.worker.set_onmessage(None);
        self.worker.set_onerror(None);
        self.worker.terminate();
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
        // Nothing waits for the reply (no call has this id); a stopped worker holds nothing.
        let args = Array::of1(&JsValue::from(self.handle));
        let unload = message(UNANSWERED, "unload", &args);
        self.worker.worker.post_message(&unload).ok();
    }
}

/// The id of a message whose reply nobody waits for (calls count up from 0).
const UNANSWERED: u32 = u32::MAX;

/// `started`, or a rejection once [`START_TIMEOUT_S`] have passed without its settling.
fn within_start_time(started: Promise) -> Promise {
    let timeout = Promise::new(&mut |_, reject| {
        let error = js_sys::Error::new(&format!("it did not start within {START_TIMEOUT_S} s"));
        if let Some(window) = web_sys::window() {
            window
                .set_timeout_with_callback_and_timeout_and_arguments_1(
                    &reject,
                    START_TIMEOUT_S * 1000,
                    &error,
                )
                .ok();
        }
    });
    Promise::race(&Array::of2(&started, &timeout))
}

/// The message that calls the worker's `call` with `args`; its reply carries `id`.
fn message(id: u32, call: &str, args: &Array) -> Object {
    let message = Object::new();
    for (key, value) in [
        ("id", JsValue::from(id)),
        ("call", JsValue::from_str(call)),
        ("args", args.into()),
    ] {
        Reflect::set(&message, &JsValue::from_str(key), &value).ok();
    }
    message
}

/// Marks a worker stopped for `why` and fails every call waiting for a reply.
fn stop(pending: &RefCell<Pending>, stopped: &RefCell<Option<String>>, why: &str) {
    stopped.borrow_mut().get_or_insert_with(|| why.to_string());
    for (_, (_, reject)) in pending.borrow_mut().drain() {
        reject.call1(&JsValue::NULL, &js_sys::Error::new(why)).ok();
    }
}
