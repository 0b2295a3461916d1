//! The network in the page: H-Net with its weights on the chosen device, and inference on the
//! stereo pair on screen.

use std::cell::{Cell, RefCell};
use std::collections::BTreeMap;
use std::rc::Rc;

use burn::module::Module;
use burn::tensor::Device;
use hnet_model::architectures::{ModelSpec, StereoModel};
use hnet_model::catheter_entry::{
    CatheterEntry, EntryReading, EntrySearch, EntrySetting, ReadEntryError, TurnedOutput,
    turned_pair,
};
use hnet_model::inference::{JoinViewsError, PredictError, StereoPair, StereoPrediction};
use hnet_model::weights::{WeightsError, WeightsHeader};
use hnet_model::{HNet, HNetConfig, HNetConfigError};
use hnet_units::mask::MaskAveraging;
use hnet_units::turn::{TurnError, turn_clockwise};
use hnet_units::{ImageSize, TipForce, View};

use crate::browser::{now_ms, yield_to_browser};
use crate::compute::Backend;
use crate::cpu_pool::{CpuPool, PoolError, WorkersStatus, pool_size};
use crate::error_text::with_causes;
use crate::force_reading::TrainingDomain;
use crate::gpu_worker::{GpuNetwork, GpuWorker, GpuWorkerError};
use crate::imaging::{WORK_SIZE, rescale_mask, rescale_rgb};
use hnet_twin::model_facts::ModelFacts;
use hnet_twin::reconstruction::physics_force::ForceCombination;

/// Input size of the untrained network the page falls back to when it ships no weights: 64×64
/// pixels.
pub const FALLBACK_INPUT: ImageSize = ImageSize::square(64);

/// Where the weights came from.
#[derive(Debug, Clone, PartialEq)]
pub enum WeightsOrigin {
    /// The weights bundled with the page.
    Bundled,
    /// A file the user loaded.
    File,
    /// Weights the user fine-tuned in the page and kept (stored in the browser).
    FineTuned,
    /// None: freshly initialised weights (the page was built without bundled weights).
    Untrained,
}

/// Where a loaded H-Net runs.
enum Runner {
    /// On Burn's flex CPU backend (WebAssembly): in the pool of CPU workers once it has started
    /// ([`Engine::start_workers`]), on the page's thread before and without it. The page's copy
    /// also joins the workers' views with the force head.
    Cpu(Box<HNet>),
    /// In the WebGPU worker ([`crate::gpu_worker`]), which holds its own copy of the network.
    WebGpu(GpuNetwork),
}

/// A loaded H-Net.
pub struct Engine {
    runner: Runner,
    /// Which backend it runs on.
    pub backend: Backend,
    /// Its input size, pixels.
    pub input: ImageSize,
    /// Parameter count.
    pub params: usize,
    /// The weights file's name.
    pub weights_name: String,
    /// Where the weights came from.
    pub origin: WeightsOrigin,
    /// The weights file's header (its provenance), when there is a file.
    pub header: Option<WeightsHeader>,
    /// The weights file (for untrained weights, their bytes), to rebuild the engine on another
    /// backend.
    pub weights: Rc<[u8]>,
    /// What the WebGPU result check found, on WebGPU ([`crate::webgpu_check`]).
    pub check: Option<String>,
    /// What the weights' force was trained on and how far off it is there, when their file
    /// records it ([`hnet_twin::model_facts`]); `None`: their accuracy is unknown.
    pub domain: Option<TrainingDomain>,
    /// The calibrated combination with the physics estimate and both estimates' intervals,
    /// when the file records one (with or without a training domain).
    pub combination: Option<ForceCombination>,
    /// Why the file's facts could not be read, when they could not.
    pub facts_error: Option<String>,
    /// How each view is read for its mask: as the file's calibration was measured
    /// ([`ModelFacts::mask_averaging`]), so that its intervals hold; one reading by default.
    pub mask_averaging: MaskAveraging,
    /// The CPU workers that read its views, once started.
    workers: RefCell<Option<Rc<CpuPool>>>,
    /// Whether the workers were asked for.
    workers_asked: Cell<bool>,
}

/// What H-Net says about one pair, at [`WORK_SIZE`].
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Catheter probability of each pixel of view A.
    pub mask_a: Vec<f32>,
    /// Catheter probability of each pixel of view B.
    pub mask_b: Vec<f32>,
    /// H-Net's tip force `(Fx, Fy, Fz)` in newtons as the page reads it; `None` when a view was
    /// read turned (its force head learned catheters that come up from the bottom of both views)
    /// or shows no catheter ([`Self::no_catheter`]).
    pub force_n: Option<TipForce>,
    /// What the force head answered, catheter or not (`None` only for a view read turned): what
    /// the WebGPU check compares, never shown as a force.
    pub head_force_n: Option<TipForce>,
    /// The edge through which each view's catheter was read as entering
    /// ([`hnet_model::catheter_entry`]).
    pub entry: [CatheterEntry; 2],
    /// Why no force is read, when a view's mask shows no catheter
    /// ([`crate::force_reading::no_catheter_found`]).
    pub no_catheter: Option<String>,
    /// Time of the forward pass and read-back, milliseconds.
    pub millis: f64,
    /// The backend it ran on.
    pub backend: &'static str,
    /// CPU workers it was spread over (0: the page's thread, or WebGPU).
    pub workers: usize,
    /// Why a view was read again, when a CPU worker stopped while reading it.
    pub redone: Option<String>,
}

impl Prediction {
    /// Why H-Net's force was left out of this prediction: a view shows no catheter, or a view
    /// was read turned.
    pub fn force_left_out(&self) -> Option<String> {
        if self.force_n.is_some() {
            return None;
        }
        if self.entry == [CatheterEntry::Bottom; 2] {
            return self.no_catheter.as_ref().map(|why| {
                format!(
                    "No force is read: {why}. H-Net answers a force for any image, a catheter in \
                     it or not; without one in both views that number would mean nothing."
                )
            });
        }
        let [a, b] = self.entry.map(CatheterEntry::name);
        Some(format!(
            "H-Net's force is not read: its force head learned catheters that come up from the \
             bottom of both views, and this pair's were read as entering view A from the {a} and \
             view B from the {b} (each view turned for its masks). The physics estimate needs no \
             such pose."
        ))
    }
}

/// Why the page has no network to run, or the network gave no prediction.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// The weights file cannot be read (the error names it).
    #[error(transparent)]
    Weights(#[from] WeightsError),
    /// The weights file holds another network.
    #[error("{file}: holds `{architecture}` weights; the page runs H-Net")]
    NotHnet {
        /// The weights file's name.
        file: String,
        /// The network it holds.
        architecture: String,
    },
    /// The network takes images that are not square.
    #[error("{file}: the network takes {size} images; the page runs square inputs only")]
    NotSquare {
        /// The weights file's name.
        file: String,
        /// Its input size.
        size: ImageSize,
    },
    /// The untrained fallback network cannot be built.
    #[error("the untrained H-Net cannot be built")]
    Untrained(#[source] HNetConfigError),
    /// The untrained network's weights cannot be written down.
    #[error("the untrained H-Net's weights cannot be written down")]
    UntrainedWeights(#[source] WeightsError),
    /// The forward pass or the read-back failed.
    #[error(transparent)]
    Predict(#[from] PredictError),
    /// A view or a mask could not be turned for its catheter's entry edge.
    #[error(transparent)]
    Turn(#[from] TurnError),
    /// The WebGPU worker failed.
    #[error(transparent)]
    WebGpu(#[from] GpuWorkerError),
    /// The CPU workers gave no reading.
    #[error(transparent)]
    Workers(#[from] PoolError),
    /// The workers' views could not be joined into a pair.
    #[error(transparent)]
    Join(#[from] JoinViewsError),
}

impl Engine {
    /// An engine on the CPU from a weights file's bytes; the file must hold H-Net weights for
    /// square images. `reason` says why the CPU is used.
    pub fn from_weights(
        bytes: Rc<[u8]>,
        name: &str,
        origin: WeightsOrigin,
        reason: String,
    ) -> Result<Self, EngineError> {
        let (model, spec, header) = StereoModel::from_weights_bytes(&bytes, &Device::flex(), name)?;
        let (StereoModel::Hnet(model), ModelSpec::Hnet(config)) = (model, spec) else {
            return Err(EngineError::NotHnet {
                file: name.to_string(),
                architecture: header.architecture,
            });
        };
        if !config.image_size.is_square() {
            return Err(EngineError::NotSquare {
                file: name.to_string(),
                size: config.image_size,
            });
        }
        // Facts that cannot be read leave the accuracy unknown, saying why; the network still
        // runs.
        let (facts, facts_error) = match ModelFacts::read(&header.provenance) {
            Ok(facts) => (facts, None),
            Err(e) => (ModelFacts::default(), Some(with_causes(&e))),
        };
        Ok(Self {
            weights_name: name.to_string(),
            origin,
            header: Some(header),
            domain: TrainingDomain::of_facts(&facts),
            combination: facts.combination().copied(),
            facts_error,
            mask_averaging: facts.mask_averaging(),
            ..Self::without_file(model, config.image_size, bytes, reason)
        })
    }

    /// An engine on the CPU for `model`, whose weights are `weights`, that came from no file.
    fn without_file(model: HNet, input: ImageSize, weights: Rc<[u8]>, reason: String) -> Self {
        Self {
            params: model.num_params(),
            runner: Runner::Cpu(Box::new(model)),
            backend: Backend::Cpu { reason },
            input,
            weights_name: "untrained".into(),
            origin: WeightsOrigin::Untrained,
            header: None,
            weights,
            check: None,
            domain: None,
            combination: None,
            facts_error: None,
            mask_averaging: MaskAveraging::Single,
            workers: RefCell::default(),
            workers_asked: Cell::new(false),
        }
    }

    /// An untrained H-Net on the CPU (paper architecture at [`FALLBACK_INPUT`]). Its
    /// freshly initialised weights are kept as a file's bytes, so that WebGPU and a later switch
    /// of backend get the same numbers.
    pub fn untrained(reason: String) -> Result<Self, EngineError> {
        let config = HNetConfig::new().with_image_size(FALLBACK_INPUT);
        let model = config
            .init(&Device::flex())
            .map_err(EngineError::Untrained)?;
        let bytes = model
            .to_weights_bytes(&config, &BTreeMap::new())
            .map_err(EngineError::UntrainedWeights)?;
        Ok(Self::without_file(
            model,
            config.image_size,
            bytes.into(),
            reason,
        ))
    }

    /// This engine on the CPU, `reason` saying why the CPU is used.
    pub fn with_cpu_reason(self, reason: String) -> Self {
        Self {
            backend: Backend::Cpu { reason },
            ..self
        }
    }

    /// This engine with what the WebGPU result check found.
    pub fn with_check(self, check: String) -> Self {
        Self {
            check: Some(check),
            ..self
        }
    }

    /// The same network on WebGPU, in `worker`, which loads the same weights. The CPU engine is
    /// kept by the caller, for the check and the fallback.
    pub async fn on_webgpu(&self, worker: &Rc<GpuWorker>) -> Result<Self, EngineError> {
        let network = worker
            .load(&self.weights, &self.weights_name, self.mask_averaging)
            .await?;
        Ok(Self {
            runner: Runner::WebGpu(network),
            backend: Backend::WebGpu,
            input: self.input,
            params: self.params,
            weights_name: self.weights_name.clone(),
            origin: self.origin.clone(),
            header: self.header.clone(),
            weights: self.weights.clone(),
            check: None,
            domain: self.domain.clone(),
            combination: self.combination,
            facts_error: self.facts_error.clone(),
            mask_averaging: self.mask_averaging,
            workers: RefCell::default(),
            workers_asked: Cell::new(false),
        })
    }

    /// Starts the pool of CPU workers for this engine's network (once; nothing on WebGPU), and
    /// reports its state to `on_change`. Until the pool is ready, and without it, the page's
    /// thread runs H-Net.
    pub fn start_workers(self: &Rc<Self>, on_change: impl Fn(WorkersStatus) + 'static) {
        let Runner::Cpu(model) = &self.runner else {
            return;
        };
        if self.workers_asked.replace(true) {
            return;
        }
        let size = pool_size();
        on_change(WorkersStatus::Starting(size));
        let on_change: Rc<dyn Fn(WorkersStatus)> = Rc::new(on_change);
        let engine = self.clone();
        let pooled = model.pooled_per_view();
        leptos::task::spawn_local(async move {
            let report = on_change.clone();
            let started = CpuPool::start(
                size,
                engine.weights.clone(),
                engine.weights_name.clone(),
                engine.input,
                pooled,
                engine.mask_averaging,
                Box::new(move |status| report(status)),
            )
            .await;
            match started {
                Ok(pool) => *engine.workers.borrow_mut() = Some(pool),
                Err(e) => on_change(WorkersStatus::PageThread(with_causes(&e))),
            }
        });
    }

    /// The CPU workers, when they run.
    fn running_workers(&self) -> Option<Rc<CpuPool>> {
        self.workers.borrow().clone().filter(|pool| pool.can_read())
    }

    /// Runs H-Net on two [`WORK_SIZE`] RGB images, resizing them to the network's input and
    /// its masks back, with each view turned for its catheter's entry edge under `entry` (a
    /// search runs four times the work). Yields to the browser first so that the busy state is
    /// painted.
    pub async fn infer(
        &self,
        view_a: &[u8],
        view_b: &[u8],
        entry: EntrySetting,
    ) -> Result<Prediction, EngineError> {
        let (a, b) = (
            rescale_rgb(view_a, WORK_SIZE, self.input),
            rescale_rgb(view_b, WORK_SIZE, self.input),
        );
        yield_to_browser().await;
        let start = now_ms();
        let pair = StereoPair {
            view_a: &a,
            view_b: &b,
        };
        let mut workers = 0;
        let mut redone = None;
        let reading: EntryReading = match &self.runner {
            Runner::Cpu(model) => {
                let on_workers = match self.running_workers() {
                    Some(pool) => {
                        workers = pool.running();
                        match on_workers(model, &pool, &a, &b, self.input, entry).await {
                            Ok((reading, why)) => {
                                redone = why;
                                Some(reading)
                            }
                            // Every worker stopped: the page's thread reads the pair.
                            Err(EngineError::Workers(PoolError::Stopped { .. })) => {
                                workers = 0;
                                None
                            }
                            Err(e) => return Err(e),
                        }
                    }
                    None => None,
                };
                match on_workers {
                    Some(reading) => reading,
                    None => {
                        let (input, averaging) = (self.input, self.mask_averaging);
                        model
                            .predict_entry_async(pair, input, &Device::flex(), entry, averaging)
                            .await?
                    }
                }
            }
            Runner::WebGpu(network) => {
                // The worker runs one pair per call: the first reading, then each further turn.
                let read = async |edges: [CatheterEntry; 2]| -> Result<TurnedOutput, EngineError> {
                    let t = turned_pair(&a, &b, self.input, edges)?;
                    let prediction: StereoPrediction =
                        network.infer(&t.view_a, &t.view_b, self.input).await?;
                    Ok(TurnedOutput::from_prediction(edges, prediction))
                };
                let first = read(entry.first_reading()).await?;
                let mut search = EntrySearch::new(entry, self.input, first);
                for edges in search.further_pairs() {
                    search.add_pair(read(edges).await?);
                }
                search.finish()?
            }
        };
        let millis = now_ms() - start;
        let [mask_a, mask_b] = &reading.masks;
        let no_catheter = crate::force_reading::no_catheter_found(mask_a, mask_b, self.input);
        Ok(Prediction {
            mask_a: rescale_mask(mask_a, self.input, WORK_SIZE),
            mask_b: rescale_mask(mask_b, self.input, WORK_SIZE),
            force_n: reading.force.filter(|_| no_catheter.is_none()),
            head_force_n: reading.force,
            entry: reading.entry,
            no_catheter,
            millis,
            backend: self.backend.label(),
            workers,
            redone,
        })
    }
}

/// `view_a` and `view_b` (RGB at `size`) read under `entry` by the CPU workers: both views of
/// the first reading at once, joined by `model`'s force head on the page's thread, then every
/// further turn a view's search asks for at once. Also says why a view was read again, when
/// one was.
async fn on_workers(
    model: &HNet,
    pool: &Rc<CpuPool>,
    view_a: &[u8],
    view_b: &[u8],
    size: ImageSize,
    entry: EntrySetting,
) -> Result<(EntryReading, Option<String>), EngineError> {
    let first = turned_pair(view_a, view_b, size, entry.first_reading())?;
    let (a, b) = futures::join!(
        pool.read_view(View::A, first.view_a),
        pool.read_view(View::B, first.view_b)
    );
    let (a, b) = (a?, b?);
    let mut redone = a.redone.or(b.redone);
    let prediction = model.join_views(a.reading, b.reading, &Device::flex())?;
    let mut search = EntrySearch::new(
        entry,
        size,
        TurnedOutput::from_prediction(first.entry, prediction),
    );
    let mut further = Vec::new();
    for (view, image) in [(View::A, view_a), (View::B, view_b)] {
        for &edge in &search.further()[view.index()] {
            let turned = turn_clockwise(image, size, 3, edge.quarter_turns())?;
            further.push((view, edge, pool.read_view(view, turned)));
        }
    }
    let (asked, reads): (Vec<_>, Vec<_>) = further
        .into_iter()
        .map(|(view, edge, read)| ((view, edge), read))
        .unzip();
    for ((view, edge), read) in asked
        .into_iter()
        .zip(futures::future::join_all(reads).await)
    {
        let read = read?;
        redone = redone.or(read.redone);
        search.add(view, edge, read.reading.mask);
    }
    Ok((search.finish()?, redone))
}

impl From<ReadEntryError> for EngineError {
    fn from(error: ReadEntryError) -> Self {
        match error {
            ReadEntryError::Predict(e) => Self::Predict(e),
            ReadEntryError::Turn(e) => Self::Turn(e),
        }
    }
}
