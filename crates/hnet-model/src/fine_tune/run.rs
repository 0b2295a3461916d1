//! [`FineTune`]: the run (feature `training`), on any device with autodiff.
//!
//! Everything the run reads back from the device (losses, gradients, scores, the best weights)
//! is read asynchronously, as WebGPU in the browser requires: the `_async` methods. The others
//! wait for them ([`burn_std::future::block_on`], Burn's own), which on the CPU returns at once.

use alloc::string::String;
use alloc::vec::Vec;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData, Transaction};
use burn_std::future::block_on;
use hnet_units::{ImageSize, TipForce};

use super::replicas::{Share, average, flatten, read_back, share_range, values};
use super::{
    EpochReport, FineTuneError, FineTuneSettings, FinishReason, HeldBackScores, TrainingPair,
};
use crate::architectures::{ModelSpec, StereoInput, StereoModel};
use crate::loss::{HNetLoss, HNetLossConfig};
use crate::metrics::{ForceAccumulator, SegmentationAccumulator};
use crate::training::{LabelledPair, RmsPropSettings, TrainingBatch, step_loss};
use crate::weights::WeightsHeader;

/// A fine-tune in progress.
pub struct FineTune {
    net: StereoModel,
    /// The starting network on the CPU: the starting values are read from it, and the best
    /// weights are written through it whatever the device trained on.
    host: StereoModel,
    /// The starting weights' values, in visiting order, for [`FineTuneSettings::start_share`]
    /// (read once; none when the share is 0).
    start: Vec<TensorData>,
    spec: ModelSpec,
    header: WeightsHeader,
    size: ImageSize,
    loss: HNetLoss,
    optimizer: ModuleOptimizer,
    settings: FineTuneSettings,
    pairs: Vec<TrainingPair>,
    /// Pairs scored after every epoch and never trained on: the domain the starting network
    /// was trained on, to show what fine-tuning costs there.
    reference: Vec<TrainingPair>,
    train: Vec<usize>,
    held_back: Vec<usize>,
    /// The autodiff device trained on, and the plain one scored on.
    device: Device,
    plain: Device,
    epoch: usize,
    /// Steps taken in the current epoch, and the sum of their losses.
    in_epoch: (usize, f64),
    /// The order of this epoch's training pairs, and the epoch it was drawn for.
    order: (Vec<usize>, Option<usize>),
    /// Whether this replica scores the held-back and reference pairs after each epoch and
    /// keeps the best network (the page's first tuning worker; the others only train).
    scores_epochs: bool,
    /// The best epoch's held-back loss and its network's values as kept, in visiting order.
    best: Option<(f64, Vec<TensorData>)>,
    since_best: usize,
    finished: Option<FinishReason>,
    rng: u64,
}

impl FineTune {
    /// Starts from the weights file `weights` (`source` names it in errors) on `device`
    /// (made an autodiff device here), with `pairs` at the network's input size.
    pub fn new(
        weights: &[u8],
        source: &str,
        pairs: Vec<TrainingPair>,
        settings: FineTuneSettings,
        device: &Device,
    ) -> Result<Self, FineTuneError> {
        let plain = device.clone().without_autodiff();
        let device = plain.clone().autodiff();
        let (net, spec, header) = StereoModel::from_weights_bytes(weights, &device, source)
            .map_err(FineTuneError::Weights)?;
        let (host, _, _) = StereoModel::from_weights_bytes(weights, &Device::flex(), source)
            .map_err(FineTuneError::Weights)?;
        let ModelSpec::Hnet(config) = &spec else {
            return Err(FineTuneError::NotHnet(spec.name()));
        };
        let (size, force_std_n) = (config.image_size, config.force_scale.map(|s| s.std_n));
        if pairs.len() < 2 {
            return Err(FineTuneError::TooFewPairs { found: pairs.len() });
        }
        check_sizes(&pairs, size)?;
        let every = settings.hold_back_every.max(2);
        let (mut train, mut held_back) = (Vec::new(), Vec::new());
        for index in 0..pairs.len() {
            if index % every == every - 1 {
                held_back.push(index);
            } else {
                train.push(index);
            }
        }
        if held_back.is_empty() {
            held_back.push(train.pop().expect("at least 2 pairs"));
        }
        let net = if settings.freeze_encoders {
            net.with_frozen_encoders()
        } else {
            net
        };
        let loss = HNetLossConfig::new().with_force_std_n(force_std_n).init();
        if !(0.0..1.0).contains(&settings.start_share) {
            return Err(FineTuneError::StartShare(settings.start_share));
        }
        Ok(Self {
            start: if settings.start_share > 0.0 {
                block_on(parameter_values(&host))?
            } else {
                Vec::new()
            },
            net,
            host,
            spec,
            header,
            size,
            loss,
            optimizer: RmsPropSettings::default().init(),
            settings,
            pairs,
            reference: Vec::new(),
            train,
            held_back,
            device,
            plain,
            epoch: 0,
            in_epoch: (0, 0.0),
            order: (Vec::new(), None),
            scores_epochs: true,
            best: None,
            since_best: 0,
            finished: None,
            rng: settings.seed ^ 0x9E37_79B9_7F4A_7C15,
        })
    }

    /// Scores `pairs` after every epoch too, never training on them: pairs of the domain the
    /// starting network was trained on (the page renders them with the twin), so that what
    /// fine-tuning costs there shows beside what it gains on the user's pairs.
    pub fn with_reference(mut self, pairs: Vec<TrainingPair>) -> Result<Self, FineTuneError> {
        check_sizes(&pairs, self.size)?;
        self.reference = pairs;
        Ok(self)
    }

    /// Trains on `pairs` too, never holding any back: pairs of the domain the starting network
    /// was trained on, rehearsed so that fine-tuning on another does not make it forget that one
    /// (docs/results.md, "Fine-tuning on a few pairs").
    pub fn with_rehearsal(mut self, pairs: Vec<TrainingPair>) -> Result<Self, FineTuneError> {
        check_sizes(&pairs, self.size)?;
        let first = self.pairs.len();
        self.train.extend(first..first + pairs.len());
        self.pairs.extend(pairs);
        Ok(self)
    }

    /// This run as a replica that only trains: it applies every step as the scoring replica
    /// does, and so holds the same weights, but scores no epoch and keeps no best network
    /// ([`Self::apply`] returns no epoch report). The page's tuning workers after the first;
    /// the last of them scores the reference pairs instead of the first
    /// ([`Self::score_reference`], after each epoch: [`Self::epochs_done`]).
    pub fn as_follower(mut self) -> Self {
        self.scores_epochs = false;
        self
    }

    /// Replicas each step is split between ([`FineTuneSettings::replicas`], at most the batch).
    pub fn replicas(&self) -> usize {
        self.settings
            .replicas
            .clamp(1, self.settings.batch_size.max(1))
    }

    /// The current network's scores on the reference pairs, when there are some, as it would be
    /// kept.
    pub fn score_reference(&self) -> Result<Option<HeldBackScores>, FineTuneError> {
        block_on(self.score_reference_async())
    }

    /// [`Self::score_reference`], waiting for the device asynchronously.
    pub async fn score_reference_async(&self) -> Result<Option<HeldBackScores>, FineTuneError> {
        if self.reference.is_empty() {
            return Ok(None);
        }
        self.score_reference_of(&self.kept()?).await.map(Some)
    }

    /// `net`'s scores on the reference pairs.
    async fn score_reference_of(&self, net: &StereoModel) -> Result<HeldBackScores, FineTuneError> {
        let all: Vec<usize> = (0..self.reference.len()).collect();
        let at = (&self.reference[..], self.size, &self.plain);
        score(&net.valid(), self.spec.input(), &self.loss, at, &all).await
    }

    /// Epochs ended so far.
    pub fn epochs_done(&self) -> usize {
        self.epoch
    }

    /// The network's input size.
    pub fn input_size(&self) -> ImageSize {
        self.size
    }

    /// Pairs trained on and held back.
    pub fn split(&self) -> (usize, usize) {
        (self.train.len(), self.held_back.len())
    }

    /// Steps in one epoch.
    pub fn steps_per_epoch(&self) -> usize {
        self.train.len().div_ceil(self.settings.batch_size.max(1))
    }

    /// Why the run ended, once it has.
    pub fn finished(&self) -> Option<FinishReason> {
        self.finished
    }

    /// The current network's scores on the held-back pairs (before the first step: the
    /// starting network's), as it would be kept ([`FineTuneSettings::start_share`]).
    pub fn score(&self) -> Result<HeldBackScores, FineTuneError> {
        block_on(self.score_async())
    }

    /// [`Self::score`], waiting for the device asynchronously.
    pub async fn score_async(&self) -> Result<HeldBackScores, FineTuneError> {
        self.score_of(&self.kept()?).await
    }

    /// `net`'s scores on the held-back pairs.
    async fn score_of(&self, net: &StereoModel) -> Result<HeldBackScores, FineTuneError> {
        let at = (&self.pairs[..], self.size, &self.plain);
        let (input, loss) = (self.spec.input(), &self.loss);
        score(&net.valid(), input, loss, at, &self.held_back).await
    }

    /// One training step on the next batch: every replica's share, one after another, then
    /// their average applied. Returns the epoch's report when the step ended an epoch, `None`
    /// otherwise (and after the run has finished).
    pub fn step(&mut self) -> Result<Option<EpochReport>, FineTuneError> {
        block_on(self.step_async())
    }

    /// [`Self::step`], waiting for the device asynchronously.
    pub async fn step_async(&mut self) -> Result<Option<EpochReport>, FineTuneError> {
        if self.finished.is_some() {
            return Ok(None);
        }
        let mut shares = Vec::with_capacity(self.replicas());
        for replica in 0..self.replicas() {
            shares.push(self.share_async(replica).await?);
        }
        self.apply_async(&shares).await
    }

    /// Replica `replica`'s share of the next step ([`share_range`] of its batch): the mean loss
    /// over its pairs and its gradients. Changes nothing but the epoch's visiting order, drawn
    /// once an epoch from the seed, so every replica draws the same.
    pub fn share(&mut self, replica: usize) -> Result<Share, FineTuneError> {
        block_on(self.share_async(replica))
    }

    /// [`Self::share`], waiting for the device asynchronously.
    pub async fn share_async(&mut self, replica: usize) -> Result<Share, FineTuneError> {
        let replicas = self.replicas();
        if replica >= replicas {
            return Err(FineTuneError::NoSuchReplica { replica, replicas });
        }
        if self.order.1 != Some(self.epoch) {
            let mut order = self.train.clone();
            shuffle(&mut order, &mut self.rng);
            self.order = (order, Some(self.epoch));
        }
        let batch_size = self.settings.batch_size.max(1);
        let at = self.in_epoch.0 * batch_size;
        let batch =
            &self.order.0[at.min(self.order.0.len())..(at + batch_size).min(self.order.0.len())];
        let mine = &batch[share_range(batch.len(), replica, replicas)];
        if self.finished.is_some() || mine.is_empty() {
            return Ok(Share {
                pairs: 0,
                loss: 0.0,
                gradients: Vec::new(),
            });
        }
        let labelled: Vec<LabelledPair<'_>> =
            mine.iter().map(|&i| self.pairs[i].labelled()).collect();
        let batch = TrainingBatch::of(&labelled, self.size, &self.device).map_err(|cause| {
            FineTuneError::OtherSize {
                size: self.size,
                cause,
            }
        })?;
        let step = step_loss(&self.net, self.spec.input(), &self.loss, &batch);
        let total = step.terms.total.clone();
        let grads = GradientsParams::from_grads(step.terms.total.backward(), &self.net);
        let gradients = flatten(&self.net, &grads).await?;
        let loss = scalar(total).await?;
        Ok(Share {
            pairs: mine.len(),
            loss,
            gradients,
        })
    }

    /// Applies the step whose shares are `shares` (every replica's, in replica order): their
    /// average, weighted by pairs, through the optimiser. Returns the epoch's report when the
    /// step ended an epoch and this replica scores epochs, `None` otherwise. A loss that is not
    /// finite ends the run ([`FinishReason::Diverged`]) without applying the step.
    pub fn apply(&mut self, shares: &[Share]) -> Result<Option<EpochReport>, FineTuneError> {
        block_on(self.apply_async(shares))
    }

    /// [`Self::apply`], waiting for the device asynchronously.
    pub async fn apply_async(
        &mut self,
        shares: &[Share],
    ) -> Result<Option<EpochReport>, FineTuneError> {
        if self.finished.is_some() {
            return Ok(None);
        }
        let pairs: usize = shares.iter().map(|s| s.pairs).sum();
        let loss =
            shares.iter().map(|s| s.pairs as f64 * s.loss).sum::<f64>() / pairs.max(1) as f64;
        if !loss.is_finite() {
            self.in_epoch = (self.in_epoch.0 + 1, self.in_epoch.1 + loss);
            return self.end_epoch(Some(FinishReason::Diverged)).await;
        }
        let grads = average(&self.net, shares, &self.plain)?;
        self.in_epoch = (self.in_epoch.0 + 1, self.in_epoch.1 + loss);
        let net = self.net.clone();
        self.net = self.optimizer.step(self.settings.learning_rate, net, grads);
        if self.in_epoch.0 >= self.steps_per_epoch() {
            return self.end_epoch(None).await;
        }
        Ok(None)
    }

    async fn end_epoch(
        &mut self,
        diverged: Option<FinishReason>,
    ) -> Result<Option<EpochReport>, FineTuneError> {
        self.epoch += 1;
        let (steps, sum) = core::mem::replace(&mut self.in_epoch, (0, 0.0));
        let train_loss = sum / steps.max(1) as f64;
        if !self.scores_epochs {
            self.finished = diverged.or_else(|| {
                (self.epoch >= self.settings.max_epochs).then_some(FinishReason::LastEpoch)
            });
            return Ok(None);
        }
        let kept = self.kept()?;
        let held_back = self.score_of(&kept).await?;
        let reference = if self.reference.is_empty() {
            None
        } else {
            Some(self.score_reference_of(&kept).await?)
        };
        let improved = diverged.is_none()
            && held_back.loss.is_finite()
            && self
                .best
                .as_ref()
                .is_none_or(|(best, _)| held_back.loss < *best);
        if improved {
            self.best = Some((held_back.loss, parameter_values(&kept).await?));
            self.since_best = 0;
        } else {
            self.since_best += 1;
        }
        let finished = diverged
            .or_else(|| (!held_back.loss.is_finite()).then_some(FinishReason::Diverged))
            .or_else(|| {
                (self.since_best >= self.settings.patience.max(1))
                    .then_some(FinishReason::NoImprovement)
            })
            .or_else(|| {
                (self.epoch >= self.settings.max_epochs).then_some(FinishReason::LastEpoch)
            });
        self.finished = finished;
        Ok(Some(EpochReport {
            epoch: self.epoch,
            train_loss,
            held_back,
            reference,
            best: improved,
            finished: finished.is_some(),
            finished_because: finished,
        }))
    }

    /// The current network as it would be kept: every weight moved
    /// [`FineTuneSettings::start_share`] of the way back to its starting value.
    fn kept(&self) -> Result<StereoModel, FineTuneError> {
        let share = self.settings.start_share;
        if share == 0.0 {
            return Ok(self.net.clone());
        }
        let mut towards = TowardsStart {
            start: self.start.iter(),
            share,
            short: false,
        };
        let kept = self.net.clone().map(&mut towards);
        if towards.short || towards.start.next().is_some() {
            return Err(FineTuneError::Readback(
                "the starting and the trained network have different parameters".into(),
            ));
        }
        Ok(kept)
    }

    /// The best epoch's network, as kept ([`FineTuneSettings::start_share`]), as a weights
    /// file: the starting file's header with `provenance` replacing its record (the caller says
    /// where it came from and drops what no longer holds, such as measured errors). `None`
    /// before an epoch improved on nothing.
    pub fn best_weights(
        &self,
        provenance: &alloc::collections::BTreeMap<String, String>,
    ) -> Result<Option<Vec<u8>>, FineTuneError> {
        let Some((_, values)) = &self.best else {
            return Ok(None);
        };
        let mut set = SetValues {
            values: values.iter(),
            short: false,
        };
        let net = self.host.clone().map(&mut set);
        if set.short || set.values.next().is_some() {
            return Err(FineTuneError::Readback(
                "the best and the starting network have different parameters".into(),
            ));
        }
        net.to_weights_bytes(&self.spec, provenance)
            .map(Some)
            .map_err(FineTuneError::Write)
    }

    /// The starting file's header (its provenance, to build the fine-tuned file's from).
    pub fn header(&self) -> &WeightsHeader {
        &self.header
    }
}

/// Moves each trained weight `share` of the way back to its starting value (`start`, in visiting
/// order); frozen weights stay exactly as they are.
struct TowardsStart<'a> {
    start: core::slice::Iter<'a, TensorData>,
    share: f64,
    short: bool,
}

impl ModuleMapper for TowardsStart<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let Some(start) = self.start.next() else {
            self.short = true;
            return param;
        };
        // A frozen weight is its start, exactly.
        if !param.is_require_grad() {
            return param;
        }
        let share = self.share;
        param.map(|trained| {
            let start = Tensor::<D>::from_data(start.clone(), &trained.device());
            trained.mul_scalar(1.0 - share) + start.mul_scalar(share)
        })
    }
}

/// Sets every float parameter to its value in `values` (in visiting order).
struct SetValues<'a> {
    values: core::slice::Iter<'a, TensorData>,
    short: bool,
}

impl ModuleMapper for SetValues<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let Some(value) = self.values.next() else {
            self.short = true;
            return param;
        };
        param.map(|old| Tensor::<D>::from_data(value.clone(), &old.device()))
    }
}

/// Every float parameter's values of `net`, in visiting order, read back in one transaction.
async fn parameter_values(net: &StereoModel) -> Result<Vec<TensorData>, FineTuneError> {
    struct Values(Transaction);
    impl ModuleVisitor for Values {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let transaction = core::mem::take(&mut self.0);
            self.0 = transaction.register(param.val());
        }
    }
    let mut values = Values(Transaction::default());
    net.visit(&mut values);
    read_back(values.0).await
}

/// The scores of `net` on the pairs `indices` (one pair per pass, without the autodiff graph,
/// its outputs read back in one transaction).
async fn score(
    net: &StereoModel,
    input: StereoInput,
    loss: &HNetLoss,
    (pairs, size, device): (&[TrainingPair], ImageSize, &Device),
    indices: &[usize],
) -> Result<HeldBackScores, FineTuneError> {
    let mut masks = SegmentationAccumulator::new();
    let mut force = ForceAccumulator::new();
    let mut loss_sum = 0.0;
    for &index in indices {
        let pair = &pairs[index];
        let batch = TrainingBatch::of(&[pair.labelled()], size, device)
            .map_err(|cause| FineTuneError::OtherSize { size, cause })?;
        let step = step_loss(net, input, loss, &batch);
        // The loss, then each view's catheter probabilities and mask, then the force.
        let mut transaction = Transaction::default().register(step.terms.total);
        let with_masks = step.outputs.mask_logits.is_some();
        if let Some([logits_a, logits_b]) = step.outputs.mask_logits {
            for (logits, target) in [(logits_a, &batch.mask_a), (logits_b, &batch.mask_b)] {
                let probabilities = burn::tensor::activation::sigmoid(logits);
                transaction = transaction.register(probabilities).register(target.clone());
            }
        }
        let estimate = step.outputs.force.filter(|_| pair.force_n.is_some());
        let with_force = estimate.is_some();
        if let Some(estimate) = estimate {
            transaction = transaction.register(estimate);
        }
        let mut read = read_back(transaction).await?.into_iter().map(values);
        let mut next = || {
            read.next().unwrap_or_else(|| {
                Err(FineTuneError::Readback(
                    "the device returned fewer outputs than asked".into(),
                ))
            })
        };
        loss_sum += f64::from(next()?.first().copied().unwrap_or(f32::NAN));
        if with_masks {
            for _ in 0..2 {
                let (predicted, target) = (next()?, next()?);
                masks
                    .push(&predicted, &target)
                    .map_err(|e| FineTuneError::Readback(e.to_string()))?;
            }
        }
        if let (true, Some(label)) = (with_force, pair.force_n) {
            let f = next()?;
            if f.len() < 3 {
                return Err(FineTuneError::Readback(alloc::format!(
                    "the force head returned {} values, not 3",
                    f.len()
                )));
            }
            force.push(TipForce::new(f[0], f[1], f[2]), label);
        }
    }
    Ok(HeldBackScores {
        pairs: indices.len(),
        loss: loss_sum / indices.len().max(1) as f64,
        catheter_iou: masks.finish().map_or(f64::NAN, |m| m.catheter.iou),
        force_mae_n: force.finish().map(|m| m.overall.mae),
        force_pairs: force.len() as usize,
    })
}

/// Refuses pairs that are not all of `size`, naming the first that is not.
fn check_sizes(pairs: &[TrainingPair], size: ImageSize) -> Result<(), FineTuneError> {
    for (index, pair) in pairs.iter().enumerate() {
        pair.labelled()
            .check_size(size, index)
            .map_err(|cause| FineTuneError::OtherSize { size, cause })?;
    }
    Ok(())
}

/// A one-element tensor's value on the host.
async fn scalar(t: Tensor<1>) -> Result<f64, FineTuneError> {
    let read = read_back(Transaction::default().register(t)).await?;
    let value = read.into_iter().next().map(values).transpose()?;
    Ok(value
        .and_then(|v| v.first().copied())
        .map_or(f64::NAN, f64::from))
}

/// Fisher-Yates with SplitMix64: the visiting order, reproducible from the seed.
fn shuffle(items: &mut [usize], state: &mut u64) {
    for i in (1..items.len()).rev() {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        items.swap(i, (z % (i as u64 + 1)) as usize);
    }
}
