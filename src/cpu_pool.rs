//! The page's pool of CPU workers: H-Net's views read off the page's thread, one worker per core
//! the browser reports (crates/hnet-cpu, each in a [`ModuleWorker`]).
//!
//! The unit of work is one view of one pair ([`hnet_model::HNet::read_view`]): a pair's two
//! views go to two workers at once, and a cine's frames keep every worker busy. The page joins a
//! pair's views with the force head on its own thread ([`hnet_model::HNet::join_views`]). Each
//! worker holds up to two views at once ([`page_query::CPU_VIEWS_PER_WORKER_DEFAULT`]), so that it
//! starts its next view the moment it finishes one, even while the page's thread is busy (fitting
//! a traced frame's rod).
//!
//! A worker that stops (its module trapped, the browser killed it, a call failed, no answer
//! within a minute) is replaced by
//! a fresh one with the same weights, and the views it was reading are read again by another
//! worker; each such reading says so ([`PooledReading::redone`]). A view that fails twice fails
//! with why. The pool needs no cross-origin isolation: workers share nothing and exchange
//! buffers by message.

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;

use futures::channel::oneshot;
use hnet_model::inference::ViewReading;
use hnet_units::mask::MaskAveraging;
use hnet_units::{ImageSize, View, with_causes};
use js_sys::{Array, Float32Array, Reflect, Uint8Array};
use wasm_bindgen::prelude::*;

use crate::browser::{self, JsError};
use crate::module_worker::{ModuleWorker, ModuleWorkerError, within};
use crate::page_query;

/// The most workers the pool starts, whatever the browser reports: each holds its own copy of
/// the network and its activations (about 60 MB at 224 px).
pub const MAX_WORKERS: usize = 8;

/// Times a view is read before its failure is reported: once, and once more by another worker
/// after the first one stopped.
const ATTEMPTS: u32 = 2;

/// A worker, in words.
const NAME: &str = "a CPU worker";

/// How long a worker may take to answer a view handed to it (reading the views handed to it
/// before, [`CpuPool::views_per_worker`]) before it counts as stopped, seconds
/// ([`page_query::CPU_VIEW_TIMEOUT_S`], unless the page's address sets
/// [`page_query::CPU_VIEW_TIMEOUT`]).
fn view_timeout_s() -> u32 {
    page_query::cpu_view_timeout_s(&browser::page_query())
}

/// Which build of the CPU workers' module the pool runs. Both read the same network with the
/// same kernels; they differ in the multiply-adds of the convolutions' products.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CpuModule {
    /// crates/hnet-cpu-fused: built with WebAssembly relaxed SIMD, whose `f32x4.relaxed_madd`
    /// the browser compiles to the CPU's fused multiply-add where it has one.
    Fused,
    /// crates/hnet-cpu: SIMD128 only, a multiply and an add; every browser with WebAssembly SIMD.
    Plain,
}

/// The smallest module that uses relaxed SIMD: one function returning `f32x4.relaxed_madd` of
/// three zero vectors. `WebAssembly.validate` accepts it only where relaxed SIMD is on (checked in
/// Node 20, whose V8 has it behind `--experimental-wasm-relaxed-simd`:
/// docs/log/2026-12-07-fused-multiply-adds-in-the-page.md).
fn relaxed_simd_probe() -> Vec<u8> {
    let mut module = vec![
        0x00, 0x61, 0x73, 0x6d, 0x01, 0x00, 0x00, 0x00, // magic, version 1
        0x01, 0x05, 0x01, 0x60, 0x00, 0x01, 0x7b, // types: () -> v128
        0x03, 0x02, 0x01, 0x00, // functions: one, of type 0
        0x0a, 0x3d, 0x01, 0x3b, 0x00, // code: one body of 59 bytes, no locals
    ];
    for _ in 0..3 {
        module.extend([0xfd, 0x0c]); // v128.const
        module.extend([0x00; 16]);
    }
    module.extend([0xfd, 0x85, 0x02, 0x0b]); // f32x4.relaxed_madd (0xfd 0x105), end
    module
}

impl CpuModule {
    /// The fused module where this browser's WebAssembly has relaxed SIMD (and the page's
    /// address does not turn it off: [`page_query::CPU_FUSED`]), else the plain one.
    pub fn for_this_browser() -> Self {
        let allowed = page_query::cpu_fused_allowed(&browser::page_query());
        let relaxed = js_sys::WebAssembly::validate(&Uint8Array::from(&relaxed_simd_probe()[..]))
            .unwrap_or(false);
        if allowed && relaxed {
            Self::Fused
        } else {
            Self::Plain
        }
    }

    /// The module's name for `www/module-worker.js` (its trunk build's file names).
    fn name(self) -> &'static str {
        match self {
            Self::Fused => "hnet-cpu-fused",
            Self::Plain => "hnet-cpu",
        }
    }

    /// In words, for the model bar.
    pub fn text(self) -> &'static str {
        match self {
            Self::Fused => "fused multiply-adds (WebAssembly relaxed SIMD)",
            Self::Plain => "multiplies and adds apart (no WebAssembly relaxed SIMD)",
        }
    }
}

/// Why the pool gave no reading.
#[derive(Debug, thiserror::Error)]
pub enum PoolError {
    /// The browser runs no workers.
    #[error("this browser runs no Web Workers")]
    NoWorkers,
    /// No worker could be started with the weights.
    #[error("no CPU worker could be started")]
    Start(#[source] ModuleWorkerError),
    /// A view failed on two workers in turn.
    #[error("view {view} failed on two CPU workers in turn")]
    Read {
        /// The view.
        view: &'static str,
        /// The last worker's failure.
        #[source]
        cause: ModuleWorkerError,
    },
    /// Every worker stopped and none could be started again.
    #[error("every CPU worker stopped ({why})")]
    Stopped {
        /// Why the last one stopped.
        why: String,
    },
}

/// One view's reading, and why it was read again, if it was.
#[derive(Debug, Clone)]
pub struct PooledReading {
    /// The view's mask and pooled features.
    pub reading: ViewReading,
    /// Why the first worker to read it gave no reading (it stopped), when another read it.
    pub redone: Option<String>,
}

/// A view waiting for a worker.
struct Task {
    view: View,
    image: Rc<[u8]>,
    attempts: u32,
    redone: Option<String>,
    reply: oneshot::Sender<Result<PooledReading, PoolError>>,
}

/// A started worker with the network loaded.
struct Member {
    worker: ModuleWorker,
    handle: u32,
}

impl Member {
    /// A fresh worker of `module` with the weights `weights` (`name` names them in errors)
    /// loaded, to read each view as `averaging` says.
    async fn start(
        module: CpuModule,
        weights: &[u8],
        name: &str,
        averaging: MaskAveraging,
    ) -> Result<Self, ModuleWorkerError> {
        let worker = ModuleWorker::spawn(module.name(), NAME)?;
        let large_tiles = page_query::large_winograd_tiles_allowed(&browser::page_query());
        let start = Array::of1(&JsValue::from_bool(large_tiles));
        worker.call("start", &start, &Array::new()).await?;
        let bytes = Uint8Array::from(weights);
        let args = Array::of3(
            &bytes,
            &JsValue::from_str(name),
            &JsValue::from_str(averaging.name()),
        );
        let handle = worker
            .call("load", &args, &Array::of1(&bytes.buffer()))
            .await?
            .as_f64()
            .ok_or_else(|| ModuleWorkerError::Call {
                worker: NAME,
                call: "load",
                cause: JsError::missing("the network's handle"),
            })?;
        Ok(Self {
            worker,
            handle: handle as u32,
        })
    }

    /// `view`'s reading of `image` (RGB at `size`) by this worker's network, whose branch pools
    /// `pooled` features. A failure stops the worker.
    async fn read(
        &self,
        view: View,
        image: &[u8],
        size: ImageSize,
        pooled: usize,
    ) -> Result<ViewReading, ModuleWorkerError> {
        let bytes = Uint8Array::from(image);
        let args = Array::of3(
            &JsValue::from(self.handle),
            &JsValue::from(view.index() as u32),
            &bytes,
        );
        // A worker that never answers (hung, or killed without an error event) counts as
        // stopped after the view's time.
        let seconds = view_timeout_s();
        let reply = within(
            self.worker
                .send("read_view", &args, &Array::of1(&bytes.buffer()))?,
            i32::try_from(seconds).unwrap_or(i32::MAX),
            &format!("no answer within {seconds} s"),
        );
        let answer = self.worker.reply("read_view", reply).await;
        if let Err(e) = &answer {
            self.worker.stop(&with_causes(e));
        }
        let values = answer?
            .dyn_into::<Float32Array>()
            .map(|v| v.to_vec())
            .unwrap_or_default();
        ViewReading::from_packed(&values, size, pooled).ok_or_else(|| {
            let why = format!(
                "it returned {} values, not view {}'s reading at {size}",
                values.len(),
                view.letter()
            );
            self.worker.stop(&why);
            ModuleWorkerError::Stopped { worker: NAME, why }
        })
    }
}

/// What the model bar says about the workers.
#[derive(Debug, Clone, PartialEq)]
pub enum WorkersStatus {
    /// The page's thread runs H-Net (WebGPU is used, or nothing is loaded yet).
    NotUsed,
    /// Workers are being started; the page's thread runs H-Net meanwhile.
    Starting(usize),
    /// `running` workers of `module` read the views; `replaced` of them replaced a worker that
    /// stopped.
    Running {
        /// Workers running.
        running: usize,
        /// Workers started again after one stopped, since the weights were loaded.
        replaced: usize,
        /// The module they run.
        module: CpuModule,
    },
    /// The page's thread runs H-Net, one core, for this reason.
    PageThread(String),
}

impl WorkersStatus {
    /// The status in two words, for the model bar (its [`WorkersStatus::text`] in the title).
    pub fn short(&self) -> String {
        match self {
            Self::Running { running, .. } => format!("{running} workers"),
            Self::Starting(_) => "starting workers".into(),
            Self::NotUsed | Self::PageThread(_) => "no workers".into(),
        }
    }

    /// The status in words.
    pub fn text(&self) -> String {
        match self {
            Self::NotUsed => "no workers".into(),
            Self::Starting(n) => format!("starting {n} workers…"),
            Self::Running {
                running,
                replaced: 0,
                module,
            } => format!("{running} workers, one per core, {}", module.text()),
            Self::Running {
                running,
                replaced,
                module,
            } => format!(
                "{running} workers, one per core, {}; {replaced} replaced after stopping",
                module.text()
            ),
            Self::PageThread(why) => format!("no workers: the page's thread, one core; {why}"),
        }
    }
}

/// The pool: a queue of views and the workers that read them.
pub struct CpuPool {
    module: CpuModule,
    weights: Rc<[u8]>,
    name: String,
    input: ImageSize,
    pooled: usize,
    averaging: MaskAveraging,
    /// One slot per worker; `None` while it is replaced, or once it could not be.
    members: RefCell<Vec<Option<Rc<Member>>>>,
    /// Views handed to each slot's worker and not yet answered.
    in_flight: RefCell<Vec<usize>>,
    /// The most views a worker holds at once ([`page_query::CPU_VIEWS_PER_WORKER_DEFAULT`],
    /// unless the page's address sets [`page_query::CPU_VIEWS_PER_WORKER`]).
    views_per_worker: usize,
    queue: RefCell<VecDeque<Task>>,
    /// Workers being started again.
    replacing: Cell<usize>,
    /// Workers started again after one stopped.
    replaced: Cell<usize>,
    /// Called whenever a worker stops or comes back, for the model bar.
    on_change: Box<dyn Fn(WorkersStatus)>,
}

/// The number of workers for this browser: the cores it reports, at most [`MAX_WORKERS`].
pub fn pool_size() -> usize {
    let cores = web_sys::window()
        .map(|w| w.navigator().hardware_concurrency())
        .filter(|n| n.is_finite() && *n >= 1.0)
        .unwrap_or(1.0);
    (cores as usize).clamp(1, MAX_WORKERS)
}

/// Whether the browser has the `Worker` constructor.
fn has_workers() -> bool {
    Reflect::has(&js_sys::global(), &JsValue::from_str("Worker")).unwrap_or(false)
}

impl CpuPool {
    /// Starts `size` workers, each loading `weights` (`name` names them), for a network of input
    /// `input` whose branch pools `pooled` features, each view read as `averaging` says. The
    /// pool runs with the workers that started; it fails only when none did.
    pub async fn start(
        size: usize,
        weights: Rc<[u8]>,
        name: String,
        input: ImageSize,
        pooled: usize,
        averaging: MaskAveraging,
        on_change: Box<dyn Fn(WorkersStatus)>,
    ) -> Result<Rc<Self>, PoolError> {
        if !has_workers() {
            return Err(PoolError::NoWorkers);
        }
        let module = CpuModule::for_this_browser();
        let started = futures::future::join_all(
            (0..size).map(|_| Member::start(module, &weights, &name, averaging)),
        )
        .await;
        let mut members = Vec::with_capacity(size);
        let mut failure = None;
        for member in started {
            match member {
                Ok(member) => members.push(Some(Rc::new(member))),
                Err(e) => failure = Some(e),
            }
        }
        if members.is_empty() {
            return Err(PoolError::Start(failure.unwrap_or(
                ModuleWorkerError::Stopped {
                    worker: NAME,
                    why: "no worker was asked for".into(),
                },
            )));
        }
        let pool = Rc::new(Self {
            module,
            weights,
            name,
            input,
            pooled,
            averaging,
            in_flight: RefCell::new(vec![0; members.len()]),
            views_per_worker: page_query::cpu_views_per_worker(&browser::page_query()),
            members: RefCell::new(members),
            queue: RefCell::default(),
            replacing: Cell::new(0),
            replaced: Cell::new(0),
            on_change,
        });
        (pool.on_change)(pool.status());
        Ok(pool)
    }

    /// The pool's state for the model bar.
    pub fn status(&self) -> WorkersStatus {
        if !self.can_read() {
            return WorkersStatus::PageThread(
                "every CPU worker stopped and none could be started again".into(),
            );
        }
        WorkersStatus::Running {
            running: self.running(),
            replaced: self.replaced.get(),
            module: self.module,
        }
    }

    /// Whether a worker runs, or one is being started again.
    pub fn can_read(&self) -> bool {
        self.running() > 0 || self.replacing.get() > 0
    }

    /// Workers running now.
    pub fn running(&self) -> usize {
        self.members.borrow().iter().flatten().count()
    }

    /// Reads `view` of one RGB image at the network's input size on the next free worker.
    pub async fn read_view(
        self: &Rc<Self>,
        view: View,
        image: Vec<u8>,
    ) -> Result<PooledReading, PoolError> {
        let (reply, answer) = oneshot::channel();
        self.queue.borrow_mut().push_back(Task {
            view,
            image: image.into(),
            attempts: 0,
            redone: None,
            reply,
        });
        self.pump();
        answer.await.unwrap_or_else(|_| {
            Err(PoolError::Stopped {
                why: "the pool was dropped".into(),
            })
        })
    }

    /// Hands queued views to the workers, each to the running one with the fewest views in hand
    /// (so that a pair's two views go to two workers), up to [`Self::views_per_worker`] each.
    fn pump(self: &Rc<Self>) {
        loop {
            if self.queue.borrow().is_empty() {
                break;
            }
            let chosen = {
                let (members, in_flight) = (self.members.borrow(), self.in_flight.borrow());
                members
                    .iter()
                    .zip(in_flight.iter())
                    .enumerate()
                    .filter(|(_, (member, views))| {
                        member.is_some() && **views < self.views_per_worker
                    })
                    .min_by_key(|(_, (_, views))| **views)
                    .and_then(|(slot, (member, _))| Some((slot, member.clone()?)))
            };
            let Some((slot, member)) = chosen else {
                break;
            };
            let Some(task) = self.queue.borrow_mut().pop_front() else {
                break;
            };
            self.in_flight.borrow_mut()[slot] += 1;
            let pool = self.clone();
            leptos::task::spawn_local(async move { pool.run(slot, member, task).await });
        }
        // No worker left, none coming back: nothing queued will be read.
        if !self.can_read() {
            let why = "none could be started again".to_string();
            for task in self.queue.borrow_mut().drain(..) {
                task.reply
                    .send(Err(PoolError::Stopped { why: why.clone() }))
                    .ok();
            }
        }
    }

    /// `member` (in `slot`) reads `task`'s view; a worker that fails is replaced and the view
    /// queued again, once.
    async fn run(self: Rc<Self>, slot: usize, member: Rc<Member>, mut task: Task) {
        let result = member
            .read(task.view, &task.image, self.input, self.pooled)
            .await;
        // A replaced worker's views no longer count against its slot (reset by `replace`).
        if self.holds(slot, &member) {
            self.in_flight.borrow_mut()[slot] -= 1;
        }
        match result {
            Ok(reading) => {
                task.reply
                    .send(Ok(PooledReading {
                        reading,
                        redone: task.redone,
                    }))
                    .ok();
            }
            Err(cause) => {
                task.attempts += 1;
                if task.attempts >= ATTEMPTS {
                    task.reply
                        .send(Err(PoolError::Read {
                            view: task.view.letter(),
                            cause,
                        }))
                        .ok();
                } else {
                    task.redone = Some(match cause {
                        ModuleWorkerError::Stopped { why, .. } => why,
                        other => with_causes(&other),
                    });
                    self.queue.borrow_mut().push_front(task);
                }
                self.replace(slot, &member);
            }
        }
        self.pump();
    }

    /// Whether `member` is the worker in `slot` now (not one replaced since).
    fn holds(&self, slot: usize, member: &Rc<Member>) -> bool {
        self.members.borrow()[slot]
            .as_ref()
            .is_some_and(|current| Rc::ptr_eq(current, member))
    }

    /// Stops `failed`, the worker of `slot`, for good and starts a fresh one there; nothing when
    /// it was replaced already (each view it held fails, and each asks).
    fn replace(self: &Rc<Self>, slot: usize, failed: &Rc<Member>) {
        if !self.holds(slot, failed) {
            return;
        }
        if let Some(member) = self.members.borrow_mut()[slot].take() {
            member.worker.stop("replaced after a failure");
        }
        self.in_flight.borrow_mut()[slot] = 0;
        self.replacing.set(self.replacing.get() + 1);
        (self.on_change)(self.status());
        let pool = self.clone();
        leptos::task::spawn_local(async move {
            let fresh = Member::start(pool.module, &pool.weights, &pool.name, pool.averaging).await;
            pool.replacing.set(pool.replacing.get() - 1);
            if let Ok(member) = fresh {
                pool.members.borrow_mut()[slot] = Some(Rc::new(member));
                pool.replaced.set(pool.replaced.get() + 1);
            }
            (pool.on_change)(pool.status());
            pool.pump();
        });
    }
}
