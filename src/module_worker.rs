//! The page's side of its module workers (`www/module-worker.js`): a WebAssembly module of its
//! own (crates/hnet-gpu, crates/hnet-tune) run off the page's thread and fetched only when the
//! page uses it. Each call becomes a message and its reply a Rust result; a worker whose call
//! failed is stopped (a module that trapped cannot be trusted again), and every call waiting on
//! it fails with why.

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::rc::Rc;

use js_sys::{Array, Function, Object, Promise, Reflect};
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{Event, MessageEvent, Worker, WorkerOptions, WorkerType};

use crate::browser::JsError;

/// The workers' script, next to the page (trunk copies it; index.html).
pub const WORKER_SCRIPT: &str = "module-worker.js";

/// Why a module worker gave no answer. `worker` names it for the user ("the WebGPU worker").
#[derive(Debug, thiserror::Error)]
pub enum ModuleWorkerError {
    /// The browser would not start the worker.
    #[error("{worker} cannot be started")]
    Spawn {
        /// The worker, in words.
        worker: &'static str,
        /// What the browser said.
        #[source]
        cause: JsError,
    },
    /// The worker stopped (its script or module could not be loaded, it crashed, or a call
    /// failed).
    #[error("{worker} stopped ({why})")]
    Stopped {
        /// The worker, in words.
        worker: &'static str,
        /// Why.
        why: String,
    },
    /// A call failed in the worker (the cause is the worker's own account).
    #[error("{worker}'s `{call}` failed")]
    Call {
        /// The worker, in words.
        worker: &'static str,
        /// The worker function called.
        call: &'static str,
        /// What the worker said.
        #[source]
        cause: JsError,
    },
}

/// The `resolve` and `reject` functions of a call waiting for its reply.
type Pending = HashMap<u32, (Function, Function)>;

/// A running module worker.
pub struct ModuleWorker {
    worker: Worker,
    /// The worker, in words ("the WebGPU worker").
    name: &'static str,
    pending: Rc<RefCell<Pending>>,
    /// Why the worker stopped, once it has.
    stopped: Rc<RefCell<Option<String>>>,
    next_id: Cell<u32>,
    _on_message: Closure<dyn FnMut(MessageEvent)>,
    _on_error: Closure<dyn FnMut(Event)>,
}

impl ModuleWorker {
    /// Starts the worker script as a module worker running `module` (`hnet-gpu`, `hnet-tune`),
    /// listening for its replies. `name` says what it is in errors.
    pub fn spawn(module: &str, name: &'static str) -> Result<Self, ModuleWorkerError> {
        let options = WorkerOptions::new();
        options.set_type(WorkerType::Module);
        options.set_name(module);
        let url = format!("{WORKER_SCRIPT}?module={module}");
        let worker =
            Worker::new_with_options(&url, &options).map_err(|e| ModuleWorkerError::Spawn {
                worker: name,
                cause: e.into(),
            })?;
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
                    .unwrap_or_else(|| format!("{WORKER_SCRIPT} could not be run for {name}"));
                stop(&pending, &stopped, &message);
            })
        };
        worker.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
        worker.set_onerror(Some(on_error.as_ref().unchecked_ref()));
        Ok(Self {
            worker,
            name,
            pending,
            stopped,
            next_id: Cell::new(0),
            _on_message: on_message,
            _on_error: on_error,
        })
    }

    /// Sends the worker a call of `call` with `args`, handing over the buffers in `transfer`;
    /// the promise settles with its reply.
    pub fn send(
        &self,
        call: &'static str,
        args: &Array,
        transfer: &Array,
    ) -> Result<Promise, ModuleWorkerError> {
        if let Some(why) = self.stopped.borrow().clone() {
            return Err(ModuleWorkerError::Stopped {
                worker: self.name,
                why,
            });
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
            return Err(ModuleWorkerError::Call {
                worker: self.name,
                call,
                cause: e.into(),
            });
        }
        Ok(reply)
    }

    /// The reply to a call of `call`.
    pub async fn reply(
        &self,
        call: &'static str,
        reply: Promise,
    ) -> Result<JsValue, ModuleWorkerError> {
        JsFuture::from(reply).await.map_err(|e| {
            let cause = JsError::from(e);
            match self.stopped.borrow().clone() {
                Some(why) => ModuleWorkerError::Stopped {
                    worker: self.name,
                    why,
                },
                None => ModuleWorkerError::Call {
                    worker: self.name,
                    call,
                    cause,
                },
            }
        })
    }

    /// Calls the worker's `call` with `args`, handing over the buffers in `transfer`. A failed
    /// call stops the worker: a module that trapped (a panic aborts it) cannot be trusted again.
    pub async fn call(
        &self,
        call: &'static str,
        args: &Array,
        transfer: &Array,
    ) -> Result<JsValue, ModuleWorkerError> {
        let reply = self.send(call, args, transfer)?;
        let result = self.reply(call, reply).await;
        if let Err(e) = &result {
            self.stop(&hnet_units::with_causes(e));
        }
        result
    }

    /// Posts a call whose reply nobody waits for.
    pub fn post(&self, call: &str, args: &Array) {
        self.worker
            .post_message(&message(UNANSWERED, call, args))
            .ok();
    }

    /// Stops the worker for `why`: every waiting and later call fails with it.
    pub fn stop(&self, why: &str) {
        self.worker.terminate();
        stop(&self.pending, &self.stopped, why);
    }

    /// Why the worker stopped, once it has.
    pub fn stopped(&self) -> Option<String> {
        self.stopped.borrow().clone()
    }
}

impl Drop for ModuleWorker {
    /// The last user of a worker stops it; its replies find no handler any more.
    fn drop(&mut self) {
        self.worker.set_onmessage(None);
        self.worker.set_onerror(None);
        self.worker.terminate();
    }
}

/// The id of a message whose reply nobody waits for (calls count up from 0).
const UNANSWERED: u32 = u32::MAX;

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

/// `reply`, or a rejection saying `why` once `seconds` have passed without its settling: a
/// worker that never answers (hung, or gone without an error event) would otherwise leave its
/// caller waiting for ever.
pub fn within(reply: Promise, seconds: i32, why: &str) -> Promise {
    let timeout = Promise::new(&mut |_, reject| {
        let error = js_sys::Error::new(why);
        if let Some(window) = web_sys::window() {
            window
                .set_timeout_with_callback_and_timeout_and_arguments_1(
                    &reject,
                    seconds * 1000,
                    &error,
                )
                .ok();
        }
    });
    Promise::race(&Array::of2(&reply, &timeout))
}
