//! One training step, written once for `hnet train` (through burn-train's learner) and the
//! page's fine-tuning (through [`crate::fine_tune`]): a batch of labelled pairs as tensors, the
//! network's forward pass on it and the loss of eq. 7 over the heads the network has, and the
//! optimiser of the paper's recipe (RMSprop).

use alloc::vec::Vec;

use burn::tensor::{Device, Tensor, TensorData};
use hnet_units::{ImageSize, TipForce};

use crate::architectures::{StereoInput, StereoModel, StereoOutputs};
use crate::inference::{InputSizeError, push_mask, push_planar};
use crate::loss::{HNetLoss, LossTerms};

/// One labelled stereo pair, at the network's input size.
#[derive(Debug, Clone, Copy)]
pub struct LabelledPair<'a> {
    /// View A, 8-bit RGB, row-major, `height·width·3` bytes.
    pub view_a: &'a [u8],
    /// View B.
    pub view_b: &'a [u8],
    /// View A's catheter mask, `height·width` bytes (255 catheter, 0 background; soft edges
    /// allowed).
    pub mask_a: &'a [u8],
    /// View B's.
    pub mask_b: &'a [u8],
    /// The tip force label `(Fx, Fy, Fz)` in newtons; `None`: the pair trains the masks only.
    pub force_n: Option<TipForce>,
}

impl LabelledPair<'_> {
    /// Whether its four buffers hold images of `size` (views RGB, masks one byte a pixel); the
    /// error names the buffer, as pair `index` of its batch.
    pub fn check_size(&self, size: ImageSize, index: usize) -> Result<(), InputSizeError> {
        let (rgb, grey) = (size.pixels() * 3, size.pixels());
        let buffers = [
            ("A", self.view_a, rgb),
            ("B", self.view_b, rgb),
            ("A's mask", self.mask_a, grey),
            ("B's mask", self.mask_b, grey),
        ];
        for (view, pixels, expected) in buffers {
            if pixels.len() != expected {
                return Err(InputSizeError {
                    pair: index,
                    view,
                    found: pixels.len(),
                    expected,
                });
            }
        }
        Ok(())
    }
}

/// A batch of `B` labelled pairs as the network and its loss read them.
#[derive(Debug, Clone)]
pub struct TrainingBatch {
    /// View A images `[B, 3, H, W]` in `[0, 1]`.
    pub view_a: Tensor<4>,
    /// View B images.
    pub view_b: Tensor<4>,
    /// View A masks `[B, 1, H, W]` in `[0, 1]`.
    pub mask_a: Tensor<4>,
    /// View B masks.
    pub mask_b: Tensor<4>,
    /// Tip forces `[B, 3]` in newtons (zero where unlabelled).
    pub force: Tensor<2>,
    /// `[B, 1]`: 1 for pairs whose force is a label, 0 for masks-only pairs.
    pub force_known: Tensor<2>,
}

impl TrainingBatch {
    /// The batch of `pairs`, all at `size`, on `device` (an autodiff device to train).
    pub fn of(
        pairs: &[LabelledPair<'_>],
        size: ImageSize,
        device: &Device,
    ) -> Result<Self, InputSizeError> {
        let [h, w] = size.height_width();
        let n = pairs.len();
        let (rgb, grey) = (size.pixels() * 3, size.pixels());
        let mut a = Vec::with_capacity(n * rgb);
        let mut b = Vec::with_capacity(n * rgb);
        let mut ma = Vec::with_capacity(n * grey);
        let mut mb = Vec::with_capacity(n * grey);
        let mut f = Vec::with_capacity(n * 3);
        let mut known = Vec::with_capacity(n);
        for (index, pair) in pairs.iter().enumerate() {
            pair.check_size(size, index)?;
            push_planar(pair.view_a, &mut a);
            push_planar(pair.view_b, &mut b);
            push_mask(pair.mask_a, &mut ma);
            push_mask(pair.mask_b, &mut mb);
            f.extend_from_slice(&pair.force_n.unwrap_or_default().newtons());
            known.push(if pair.force_n.is_some() { 1.0f32 } else { 0.0 });
        }
        let image = |data| Tensor::from_data(TensorData::new(data, [n, 3, h, w]), device);
        let mask = |data| Tensor::from_data(TensorData::new(data, [n, 1, h, w]), device);
        Ok(Self {
            view_a: image(a),
            view_b: image(b),
            mask_a: mask(ma),
            mask_b: mask(mb),
            force: Tensor::from_data(TensorData::new(f, [n, 3]), device),
            force_known: Tensor::from_data(TensorData::new(known, [n, 1]), device),
        })
    }

    /// Pairs in the batch.
    pub fn len(&self) -> usize {
        self.force.dims()[0]
    }

    /// Whether the batch holds no pair.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The network's outputs on a batch and their loss.
#[derive(Debug, Clone)]
pub struct StepLoss {
    /// What the network produced.
    pub outputs: StereoOutputs,
    /// The loss of eq. 7 and its terms (on the autodiff graph when the batch is on an autodiff
    /// device: `terms.total.backward()` gives the step's gradients).
    pub terms: LossTerms,
}

/// The forward pass of `net` (reading `input`) on `batch` and its loss: the one training step's
/// computation, before the backward pass and the optimiser. The force term is averaged over the
/// labelled pairs only, so that masks-only pairs never pull the force head.
pub fn step_loss(
    net: &StereoModel,
    input: StereoInput,
    loss: &HNetLoss,
    batch: &TrainingBatch,
) -> StepLoss {
    let masks = [batch.mask_a.clone(), batch.mask_b.clone()];
    let views = match input {
        StereoInput::Images => [batch.view_a.clone(), batch.view_b.clone()],
        StereoInput::Masks => masks.clone(),
    };
    let outputs = net.forward(views, masks.clone());
    let terms = loss.forward_heads(
        outputs.mask_logits.clone(),
        outputs.force.clone(),
        masks,
        batch.force.clone(),
        Some(batch.force_known.clone()),
    );
    StepLoss { outputs, terms }
}

/// The optimiser of the paper's recipe: RMSprop (Keras' defaults unless a config says
/// otherwise).
#[cfg(feature = "training")]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RmsPropSettings {
    /// Smoothing constant (Keras' `rho`, 0.9).
    pub alpha: f32,
    /// Momentum (Keras' 0).
    pub momentum: f32,
    /// Epsilon (Keras' 1e-7).
    pub epsilon: f32,
}

#[cfg(feature = "training")]
impl Default for RmsPropSettings {
    fn default() -> Self {
        Self {
            alpha: 0.9,
            momentum: 0.0,
            epsilon: 1e-7,
        }
    }
}

#[cfg(feature = "training")]
impl RmsPropSettings {
    /// The optimiser, for any module.
    pub fn init(&self) -> burn::optim::ModuleOptimizer {
        burn::optim::RmsPropConfig::new()
            .with_alpha(self.alpha)
            .with_momentum(self.momentum)
            .with_epsilon(self.epsilon)
            .init()
    }
}
