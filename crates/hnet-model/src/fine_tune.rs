//! Fine-tuning a trained H-Net on a few labelled pairs: the page's "Fine-tune on my pairs"
//! (run in its worker, crates/hnet-tune), on any device with autodiff. The run itself,
//! [`FineTune`], needs the feature `training`; its settings and reports do not, so that the
//! page reads them without the training stack.
//!
//! The pairs are split once into the ones trained on and the ones held back (every
//! [`FineTuneSettings::hold_back_every`]-th pair, at least one): the held-back pairs score the
//! network before and after, and choose the best epoch (early stopping on their loss). The
//! training step is [`crate::training`]'s, the one `hnet train` takes; by default the encoders are
//! frozen (few pairs teach the decoder and the heads, not the features), and an epoch whose loss
//! is not finite ends the run with the best weights so far kept.

use alloc::string::String;
use alloc::vec::Vec;

use hnet_units::{ImageSize, TipForce};

use crate::inference::InputSizeError;
use crate::training::LabelledPair;
use crate::weights::WeightsError;

#[cfg(feature = "training")]
mod replicas;
#[cfg(feature = "training")]
mod run;
#[cfg(feature = "training")]
pub use replicas::{Share, share_range};
#[cfg(feature = "training")]
pub use run::FineTune;

/// How a fine-tune runs. The defaults suit the tens of pairs a user labels in the page.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct FineTuneSettings {
    /// Most epochs.
    pub max_epochs: usize,
    /// Stop when the held-back loss has not improved for this many epochs.
    pub patience: usize,
    /// Pairs per step.
    pub batch_size: usize,
    /// RMSprop's learning rate. The default, 2e-4, twice the bundled model's last stage's: on 20
    /// pairs of a blurrier detector it learned more than 1e-4 in 12 epochs and nearly what 3e-4
    /// did, at a smaller cost to the bench (docs/results.md, "Fine-tuning on a few pairs").
    pub learning_rate: f64,
    /// Keep the encoders' weights as they are (the decoders and heads learn).
    pub freeze_encoders: bool,
    /// Hold back every n-th pair (at least one) to score before and after.
    pub hold_back_every: usize,
    /// Seed of the order the pairs are visited in.
    pub seed: u64,
    /// Replicas each step's batch is split between, their gradients averaged (weighted by
    /// their pairs): the page's tuning workers, one per core and at most [`Self::batch_size`].
    /// Natively the replicas run one after another, so the same settings give the same
    /// numbers on either side. With 1 (the default) the step is `hnet train`'s.
    pub replicas: usize,
    /// Share of the starting weights in the network scored, kept and saved: after each epoch
    /// every weight is moved this far back towards where it started (weight-space ensembling,
    /// WiSE-FT: Wortsman et al., CVPR 2022). Training itself goes on from the trained weights.
    /// The default, 0.15: on 20 pairs of a blurrier detector the bench lost 0.013-0.017 of
    /// catheter IoU where the trained weights lost 0.019-0.021, and the blurred pairs kept
    /// 0.806-0.818 (0.818-0.826 trained; docs/results.md, "Fine-tuning on a few pairs"). 0 keeps
    /// the trained weights as they are.
    pub start_share: f64,
}

impl Default for FineTuneSettings {
    fn default() -> Self {
        Self {
            max_epochs: 12,
            patience: 4,
            batch_size: 2,
            learning_rate: 2e-4,
            freeze_encoders: true,
            hold_back_every: 5,
            seed: 0,
            replicas: 1,
            start_share: 0.15,
        }
    }
}

/// One labelled pair, owned: what the page sends the worker.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingPair {
    /// View A, 8-bit RGB at the network's input size.
    pub view_a: Vec<u8>,
    /// View B.
    pub view_b: Vec<u8>,
    /// View A's catheter mask (255 catheter).
    pub mask_a: Vec<u8>,
    /// View B's.
    pub mask_b: Vec<u8>,
    /// The tip force label in newtons, where the pair has one (masks only otherwise).
    pub force_n: Option<TipForce>,
}

impl TrainingPair {
    /// The pair as a training step reads it.
    pub fn labelled(&self) -> LabelledPair<'_> {
        LabelledPair {
            view_a: &self.view_a,
            view_b: &self.view_b,
            mask_a: &self.mask_a,
            mask_b: &self.mask_b,
            force_n: self.force_n,
        }
    }
}

/// Why a fine-tune cannot start or go on.
#[derive(Debug, thiserror::Error)]
pub enum FineTuneError {
    /// The weights are not a network this can fine-tune.
    #[error("the weights cannot be fine-tuned")]
    Weights(#[source] WeightsError),
    /// Only H-Net is fine-tuned here.
    #[error("only H-Net weights can be fine-tuned here, not {0}")]
    NotHnet(&'static str),
    /// Too few pairs to train on some and score on others.
    #[error(
        "fine-tuning needs at least 2 labelled pairs (one to train on, one held back to score \
         on); {found} given"
    )]
    TooFewPairs {
        /// Pairs given.
        found: usize,
    },
    /// A pair is not at the network's input size.
    #[error("the pairs must be at the network's input size, {size}")]
    OtherSize {
        /// The network's input size.
        size: ImageSize,
        /// Which pair and buffer.
        #[source]
        cause: InputSizeError,
    },
    /// Reading the network's outputs back failed.
    #[error("reading the network's outputs failed: {0}")]
    Readback(String),
    /// The weights could not be written.
    #[error("the fine-tuned weights cannot be written")]
    Write(#[source] WeightsError),
    /// The replicas' shares of a step do not fit this network (another network's, or none with
    /// a pair).
    #[error(
        "the replicas' shares of a step do not fit this network: {pairs} pairs, gradients of \
         {lengths:?} values"
    )]
    Shares {
        /// Pairs over all shares.
        pairs: usize,
        /// Each share's gradient values.
        lengths: Vec<usize>,
    },
    /// The share of the starting weights kept is not in `[0, 1)`.
    #[error(
        "the share of the starting weights kept must be at least 0 and below 1 (0 keeps the \
         trained weights), not {0}"
    )]
    StartShare(f64),
    /// A replica was asked for a share beyond the settings' replicas.
    #[error("replica {replica} asked for, of {replicas}")]
    NoSuchReplica {
        /// The replica asked for, from 0.
        replica: usize,
        /// Replicas in the settings.
        replicas: usize,
    },
}

/// How the network does on the held-back pairs.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeldBackScores {
    /// Held-back pairs.
    pub pairs: usize,
    /// The loss of eq. 7 on them (masks, and the force where labelled).
    pub loss: f64,
    /// Catheter IoU over both views of every held-back pair (masks thresholded at
    /// [`hnet_units::mask::MASK_THRESHOLD`]).
    pub catheter_iou: f64,
    /// Mean absolute error of the force head over the labelled held-back pairs, newtons.
    pub force_mae_n: Option<f64>,
    /// Held-back pairs with a force label.
    pub force_pairs: usize,
}

impl core::fmt::Display for HeldBackScores {
    /// `catheter IoU 0.912, force MAE 0.031 N`: what the page's table and the weights' provenance
    /// say.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "catheter IoU {:.3}", self.catheter_iou)?;
        if let Some(mae) = self.force_mae_n {
            write!(f, ", force MAE {mae:.3} N")?;
        }
        Ok(())
    }
}

/// What one epoch did.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpochReport {
    /// The epoch, from 1.
    pub epoch: usize,
    /// Mean training loss over its steps.
    pub train_loss: f64,
    /// The held-back pairs after it.
    pub held_back: HeldBackScores,
    /// The reference pairs after it ([`FineTune::with_reference`]), when there are some.
    #[serde(default)]
    pub reference: Option<HeldBackScores>,
    /// Whether it is the best epoch so far (lowest held-back loss): its weights are the result.
    pub best: bool,
    /// Whether the run is over: patience spent, the last epoch done, or a loss not finite.
    pub finished: bool,
    /// Why it finished, when it has.
    pub finished_because: Option<FinishReason>,
}

/// Why a fine-tune ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum FinishReason {
    /// Every epoch asked for was run.
    LastEpoch,
    /// The held-back loss stopped improving.
    NoImprovement,
    /// A loss was not finite: the run diverged; the best weights before it are kept.
    Diverged,
}

impl core::fmt::Display for FinishReason {
    /// Why the run ended, in words: what `hnet fine-tune` says at its end.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::LastEpoch => "every epoch asked for was run",
            Self::NoImprovement => "the held-back loss stopped improving",
            Self::Diverged => "a loss was not finite; the best weights before it are kept",
        })
    }
}
