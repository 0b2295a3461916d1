//! The multitask loss of the paper (eq. 7):
//! `L = β1·BCE(mask A) + β2·BCE(mask B) + β3·MSE(force)`, and optionally our outline term
//! `+ β4·(outline A + outline B)` ([`outline_divergence`]), which teaches the masks' sub-pixel
//! edges.

use burn::config::Config;
use burn::tensor::Tensor;
use burn::tensor::activation::log_sigmoid;
use burn::tensor::module::max_pool2d;
use burn::tensor::ops::MaxPoolOptions;

use crate::model::HNetOutput;

/// Weights of the three loss terms. The paper weighs them equally.
#[derive(Config, Debug, PartialEq)]
pub struct HNetLossConfig {
    /// β1: view A's binary cross-entropy.
    #[config(default = 1.0)]
    pub beta_a: f64,
    /// β2: view B's binary cross-entropy.
    #[config(default = 1.0)]
    pub beta_b: f64,
    /// β3: mean squared error of the tip force (in N², or in standardised units with
    /// `force_std_n`).
    #[config(default = 1.0)]
    pub beta_force: f64,
    /// When set, the force error of each axis is divided by this standard deviation (N) before
    /// squaring: the force term is then the MSE of standardised forces, of unit scale whatever
    /// the force range (set with [`crate::model::HNetConfig::force_scale`]).
    pub force_std_n: Option<[f64; 3]>,
    /// β4: weight of each view's [`outline_divergence`]; `None` is 0, the paper's loss (an
    /// option so that configs and run folders written before it still load). The mean BCE over
    /// a view weighs the catheter's outline at under 1 % of its pixels, so a network can leave
    /// its edges at whole pixels, while the rod fit reads the centreline from the edges' grey
    /// levels to a tenth of a pixel.
    pub outline: Option<f64>,
}

impl HNetLossConfig {
    /// The loss with these weights.
    pub fn init(&self) -> HNetLoss {
        HNetLoss {
            config: self.clone(),
        }
    }
}

/// The H-Net loss. Build it with [`HNetLossConfig::init`].
#[derive(Debug, Clone)]
pub struct HNetLoss {
    config: HNetLossConfig,
}

/// The total loss and its three unweighted terms, each a one-element tensor.
#[derive(Debug, Clone)]
pub struct LossTerms {
    /// `β1·bce_a + β2·bce_b + β3·mse + β4·outline`.
    pub total: Tensor<1>,
    /// Mean binary cross-entropy of view A's mask.
    pub bce_a: Tensor<1>,
    /// Mean binary cross-entropy of view B's mask.
    pub bce_b: Tensor<1>,
    /// Mean squared error of the force over the batch and the three axes, in N² (standardised
    /// units with [`HNetLossConfig::force_std_n`]).
    pub mse: Tensor<1>,
    /// The two views' [`outline_divergence`]s, summed (zero when β4 is 0 or the network has no
    /// masks).
    pub outline: Tensor<1>,
}

impl HNetLoss {
    /// β4, 0 when unset.
    fn outline_weight(&self) -> f64 {
        self.config.outline.unwrap_or(0.0)
    }

    /// The loss of `output` against target masks `[B, 1, H, W]` (values in `[0, 1]`; soft,
    /// anti-aliased masks are allowed) and target forces `[B, 3]` in newtons.
    pub fn forward(
        &self,
        output: &HNetOutput,
        mask_a: Tensor<4>,
        mask_b: Tensor<4>,
        force: Tensor<2>,
    ) -> LossTerms {
        self.forward_heads(
            Some([output.mask_logits_a.clone(), output.mask_logits_b.clone()]),
            Some(output.force.clone()),
            [mask_a, mask_b],
            force,
            None,
        )
    }

    /// The same loss for a network that may lack a head (the baselines: a segmentation-only
    /// network has no force, Y-Net no masks): an absent head's terms are zero. `mask_logits`
    /// are views A and B's logits, `masks` their targets.
    ///
    /// `force_known` (`[B, 1]`, 1 or 0) marks the pairs whose force is a label: the force term
    /// is then the mean over those pairs only (zero when there are none), so that pairs with
    /// masks alone teach segmentation without pulling the force head. `None`: every pair's.
    pub fn forward_heads(
        &self,
        mask_logits: Option<[Tensor<4>; 2]>,
        force: Option<Tensor<2>>,
        masks: [Tensor<4>; 2],
        target_force: Tensor<2>,
        force_known: Option<Tensor<2>>,
    ) -> LossTerms {
        let device = target_force.device();
        let zero = || Tensor::<1>::zeros([1], &device);
        let [mask_a, mask_b] = masks;
        let (bce_a, bce_b, outline) = match mask_logits {
            Some([logits_a, logits_b]) => {
                let outline = if self.outline_weight() > 0.0 {
                    outline_divergence(logits_a.clone(), mask_a.clone())
                        + outline_divergence(logits_b.clone(), mask_b.clone())
                } else {
                    zero()
                };
                (
                    binary_cross_entropy_with_logits(logits_a, mask_a),
                    binary_cross_entropy_with_logits(logits_b, mask_b),
                    outline,
                )
            }
            None => (zero(), zero(), zero()),
        };
        let mse = match force {
            Some(force) => {
                let error = match self.config.force_std_n {
                    None => force - target_force,
                    Some(std_n) => {
                        let std = Tensor::<2>::from_floats([std_n.map(|s| s as f32)], &device);
                        (force - target_force) / std
                    }
                };
                let squared = error.square();
                match force_known {
                    None => squared.mean(),
                    Some(known) => {
                        // Sum over labelled pairs / (3 · their count), at least one pair.
                        let labelled = known.clone().sum().clamp_min(1.0).mul_scalar(3.0);
                        (squared * known).sum() / labelled
                    }
                }
            }
            None => zero(),
        };
        let total = bce_a.clone().mul_scalar(self.config.beta_a)
            + bce_b.clone().mul_scalar(self.config.beta_b)
            + mse.clone().mul_scalar(self.config.beta_force)
            + outline.clone().mul_scalar(self.outline_weight());
        LossTerms {
            total,
            bce_a,
            bce_b,
            mse,
            outline,
        }
    }
}

/// Mean binary cross-entropy between `sigmoid(logits)` and `targets`, computed from the logits
/// so that it stays finite for confident predictions:
/// `-(t·log σ(x) + (1-t)·log σ(-x))`.
pub fn binary_cross_entropy_with_logits<const D: usize>(
    logits: Tensor<D>,
    targets: Tensor<D>,
) -> Tensor<1> {
    cross_entropy_per_element(logits, targets).mean()
}

/// `-(t·log σ(x) + (1-t)·log σ(-x))` for each element, from the logits.
fn cross_entropy_per_element<const D: usize>(logits: Tensor<D>, targets: Tensor<D>) -> Tensor<D> {
    let positive = log_sigmoid(logits.clone()) * targets.clone();
    let negative = log_sigmoid(logits.neg()) * targets.neg().add_scalar(1.0);
    (positive + negative).neg()
}

/// Target coverage strictly between this and 1 minus it is the outline (the twin's anti-aliased
/// edge falls from 1 to 0 over about one pixel).
pub const OUTLINE_MIN_COVERAGE: f64 = 0.02;

/// The mean Kullback-Leibler divergence of the masks' probabilities `sigmoid(logits)` from the
/// target coverage over the outline band of masks `[B, 1, H, W]`: the pixels whose target lies
/// strictly between [`OUTLINE_MIN_COVERAGE`] and 1 minus it, and their 8 neighbours (where a
/// network's edge may sit a pixel off). It is the band's BCE less the targets' own entropy, so it is zero exactly when the
/// probabilities equal the coverage, and its gradient in the logits is the BCE's, `σ(x) - t`,
/// which does not vanish for a confident wrong edge. Zero where no target has an outline (binary
/// or empty masks).
pub fn outline_divergence(logits: Tensor<4>, targets: Tensor<4>) -> Tensor<1> {
    // t·(1 - t) > c·(1 - c) exactly where c < t < 1 - c.
    let bound = OUTLINE_MIN_COVERAGE * (1.0 - OUTLINE_MIN_COVERAGE);
    let edge = (targets.clone() * targets.clone().neg().add_scalar(1.0))
        .greater_elem(bound)
        .float();
    let band = max_pool2d(
        edge,
        MaxPoolOptions::new([3, 3])
            .with_stride([1, 1])
            .with_padding([1, 1]),
    );
    let cross_entropy = cross_entropy_per_element(logits, targets.clone());
    let t = targets.clamp(1e-6, 1.0 - 1e-6);
    let entropy = (t.clone() * t.clone().log()
        + t.clone().neg().add_scalar(1.0) * t.neg().add_scalar(1.0).log())
    .neg();
    ((cross_entropy - entropy) * band.clone()).sum() / band.sum().clamp_min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData, Tolerance};

    #[test]
    fn bce_matches_hand_computed_values_and_stays_finite() {
        let device = Device::flex();
        let logits = Tensor::<1>::from_floats([0.0, 0.0, 2.0, -2.0, 100.0, -100.0], &device);
        let targets = Tensor::<1>::from_floats([0.0, 1.0, 1.0, 1.0, 0.0, 0.0], &device);
        // ln 2, ln 2, ln(1 + e^-2), ln(1 + e^2), 100 (+ e^-100), ~0.
        let expected = [
            2.0f64.ln(),
            2.0f64.ln(),
            (1.0 + (-2.0f64).exp()).ln(),
            (1.0 + 2.0f64.exp()).ln(),
            100.0,
            0.0,
        ];
        let mean = expected.iter().sum::<f64>() / expected.len() as f64;
        let bce = binary_cross_entropy_with_logits(logits, targets);
        bce.into_data()
            .assert_approx_eq::<f32>(&TensorData::from([mean as f32]), Tolerance::absolute(1e-4));
    }

    #[test]
    fn outline_error_covers_the_edge_and_its_neighbours_only() {
        let device = Device::flex();
        // A 3 x 4 target with one edge pixel (coverage 0.5) at row 1, column 1: the band is
        // columns 0-2 of every row (9 pixels); column 3 lies outside it.
        let targets = Tensor::<4>::from_floats(
            [[[
                [0.0, 0.0, 0.0, 1.0],
                [0.0, 0.5, 0.0, 1.0],
                [0.0, 0.0, 0.0, 1.0],
            ]]],
            &device,
        );
        // Every probability 0.5: no divergence on the edge pixel, ln 2 on its 8 neighbours.
        let logits = Tensor::<4>::zeros([1, 1, 3, 4], &device);
        let expected = 8.0 * 2.0f32.ln() / 9.0;
        outline_divergence(logits.clone(), targets)
            .into_data()
            .assert_approx_eq::<f32>(&TensorData::from([expected]), Tolerance::absolute(1e-4));
        // Binary targets have no outline: no error whatever the logits.
        let binary = Tensor::<4>::from_floats([[[[0.0, 1.0, 1.0, 0.0]]]], &device);
        outline_divergence(Tensor::<4>::zeros([1, 1, 1, 4], &device), binary)
            .into_data()
            .assert_approx_eq::<f32>(&TensorData::from([0.0f32]), Tolerance::absolute(1e-6));
    }
}
