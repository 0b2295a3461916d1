//! The paper's evaluation metrics (section III.B), on plain numbers so that the command-line
//! tool, the browser app and the tests compute them the same way without a tensor backend.
//!
//! Both accumulators are fed sample by sample and summarise a whole set at the end, so the
//! numbers do not depend on how the set was batched.
//!
//! - Force (Table I): MAE, MSE, RMSE and R² per axis, and R/M = RMSE / max|F| (the error relative
//!   to the largest force magnitude of that axis in the set) and RMSE / (max F - min F).
//! - Segmentation (Table II): pixel accuracy, and IoU and Dice of both classes (catheter and
//!   background) with their means (mIoU, mDice), from the confusion counts of the whole set.
//!
//! A value that is undefined for the data, such as R² of a constant target, is `None` (`null` in
//! JSON) rather than NaN.

use hnet_units::TipForce;
use hnet_units::mask::is_catheter;
use serde::{Deserialize, Serialize};

/// The force axes, in the order used everywhere: `(Fx, Fy, Fz)`.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// Running sums of one force axis. The target's spread uses Welford's update so that R² stays
/// accurate for forces that vary little around a large offset.
#[derive(Debug, Clone, Copy, Default)]
struct AxisSums {
    n: u64,
    sum_abs_error: f64,
    sum_squared_error: f64,
    target_mean: f64,
    target_m2: f64,
    max_abs_target: f64,
    min_target: f64,
    max_target: f64,
}

impl AxisSums {
    fn push(&mut self, predicted: f64, target: f64) {
        let error = predicted - target;
        self.n += 1;
        self.sum_abs_error += error.abs();
        self.sum_squared_error += error * error;
        let delta = target - self.target_mean;
        self.target_mean += delta / self.n as f64;
        self.target_m2 += delta * (target - self.target_mean);
        self.max_abs_target = self.max_abs_target.max(target.abs());
        if self.n == 1 {
            self.min_target = target;
            self.max_target = target;
        } else {
            self.min_target = self.min_target.min(target);
            self.max_target = self.max_target.max(target);
        }
    }

    fn metrics(&self) -> AxisMetrics {
        let n = self.n as f64;
        let mse = self.sum_squared_error / n;
        let rmse = mse.sqrt();
        let ratio = |denominator: f64| (denominator > 0.0).then(|| rmse / denominator);
        AxisMetrics {
            mae: self.sum_abs_error / n,
            mse,
            rmse,
            r2: (self.target_m2 > 0.0).then(|| 1.0 - self.sum_squared_error / self.target_m2),
            r_over_m: ratio(self.max_abs_target),
            r_over_range: ratio(self.max_target - self.min_target),
        }
    }
}

/// Force errors of one axis (or their summary over the three axes), in newtons.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AxisMetrics {
    /// Mean absolute error (N).
    pub mae: f64,
    /// Mean squared error (N²).
    pub mse: f64,
    /// Root mean squared error (N).
    pub rmse: f64,
    /// Coefficient of determination; `None` when the target is constant (R² is undefined).
    pub r2: Option<f64>,
    /// RMSE / max|F|; `None` when every target is zero.
    pub r_over_m: Option<f64>,
    /// RMSE / (max F − min F); `None` when the target is constant.
    pub r_over_range: Option<f64>,
}

/// Force metrics of a set (the paper's Table I).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceMetrics {
    /// Number of stereo pairs.
    pub samples: u64,
    /// Per axis, in the order x, y, z.
    pub axes: [AxisMetrics; 3],
    /// Over the three axes: MAE, MSE and RMSE pooled over all `3·samples` values; R², R/M and
    /// RMSE/range are the mean of the per-axis values (`None` if any axis has none).
    pub overall: AxisMetrics,
}

/// Collects predicted and true tip forces and summarises them as [`ForceMetrics`].
#[derive(Debug, Clone, Default)]
pub struct ForceAccumulator {
    axes: [AxisSums; 3],
}

impl ForceAccumulator {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one stereo pair's predicted and true force `(Fx, Fy, Fz)` in newtons.
    pub fn push(&mut self, predicted: TipForce, target: TipForce) {
        for (axis, (p, t)) in self
            .axes
            .iter_mut()
            .zip(predicted.newtons().iter().zip(target.newtons()))
        {
            axis.push(f64::from(*p), f64::from(t));
        }
    }

    /// Number of pairs added so far.
    pub fn len(&self) -> u64 {
        self.axes[0].n
    }

    /// Whether nothing was added yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The metrics of everything added, or `None` if nothing was.
    pub fn finish(&self) -> Option<ForceMetrics> {
        if self.is_empty() {
            return None;
        }
        let axes = self.axes.map(|a| a.metrics());
        let n = 3.0 * self.len() as f64;
        let mse = self.axes.iter().map(|a| a.sum_squared_error).sum::<f64>() / n;
        let mean_of = |f: fn(&AxisMetrics) -> Option<f64>| {
            axes.iter().map(f).sum::<Option<f64>>().map(|sum| sum / 3.0)
        };
        Some(ForceMetrics {
            samples: self.len(),
            axes,
            overall: AxisMetrics {
                mae: self.axes.iter().map(|a| a.sum_abs_error).sum::<f64>() / n,
                mse,
                rmse: mse.sqrt(),
                r2: mean_of(|a| a.r2),
                r_over_m: mean_of(|a| a.r_over_m),
                r_over_range: mean_of(|a| a.r_over_range),
            },
        })
    }
}

/// IoU and Dice of one class.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClassMetrics {
    /// Intersection over union. 1 when the class is absent from both prediction and target.
    pub iou: f64,
    /// Dice coefficient (F1). 1 when the class is absent from both prediction and target.
    pub dice: f64,
}

/// Segmentation metrics of one head over a set (the paper's Table II).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SegmentationMetrics {
    /// Number of pixels compared.
    pub pixels: u64,
    /// Fraction of pixels whose class is right.
    pub accuracy: f64,
    /// The catheter class.
    pub catheter: ClassMetrics,
    /// The background class.
    pub background: ClassMetrics,
    /// Mean IoU over the two classes.
    pub miou: f64,
    /// Mean Dice over the two classes.
    pub mdice: f64,
}

/// A predicted mask and its target do not have the same number of pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("predicted mask has {predicted} pixels but the target has {target}")]
pub struct MaskSizeMismatch {
    /// Pixels in the prediction.
    pub predicted: usize,
    /// Pixels in the target.
    pub target: usize,
}

/// What a predicted pixel is against its target, catheter being the positive class.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelOutcome {
    /// Catheter in both.
    Found,
    /// Catheter in the target only.
    Missed,
    /// Catheter in the prediction only.
    Spurious,
    /// Catheter in neither.
    Background,
}

impl PixelOutcome {
    /// The outcome of catheter probability `predicted` against `target`, each thresholded at
    /// [`hnet_units::mask::MASK_THRESHOLD`].
    pub fn of(predicted: f32, target: f32) -> Self {
        match (is_catheter(predicted), is_catheter(target)) {
            (true, true) => Self::Found,
            (false, true) => Self::Missed,
            (true, false) => Self::Spurious,
            (false, false) => Self::Background,
        }
    }
}

/// Confusion counts of one segmentation head, catheter being the positive class.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SegmentationAccumulator {
    true_positive: u64,
    false_positive: u64,
    false_negative: u64,
    true_negative: u64,
}

impl SegmentationAccumulator {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one mask: `predicted` and `target` hold per-pixel catheter probabilities in the same
    /// pixel order; each is thresholded at [`hnet_units::mask::MASK_THRESHOLD`].
    pub fn push(&mut self, predicted: &[f32], target: &[f32]) -> Result<(), MaskSizeMismatch> {
        if predicted.len() != target.len() {
            return Err(MaskSizeMismatch {
                predicted: predicted.len(),
                target: target.len(),
            });
        }
        for (&p, &t) in predicted.iter().zip(target) {
            match PixelOutcome::of(p, t) {
                PixelOutcome::Found => self.true_positive += 1,
                PixelOutcome::Spurious => self.false_positive += 1,
                PixelOutcome::Missed => self.false_negative += 1,
                PixelOutcome::Background => self.true_negative += 1,
            }
        }
        Ok(())
    }

    /// Adds the counts of another accumulator (a batch computed elsewhere).
    pub fn merge(&mut self, other: &Self) {
        self.true_positive += other.true_positive;
        self.false_positive += other.false_positive;
        self.false_negative += other.false_negative;
        self.true_negative += other.true_negative;
    }

    /// Number of pixels added so far.
    pub fn pixels(&self) -> u64 {
        self.true_positive + self.false_positive + self.false_negative + self.true_negative
    }

    /// The metrics of everything added, or `None` if nothing was.
    pub fn finish(&self) -> Option<SegmentationMetrics> {
        let pixels = self.pixels();
        if pixels == 0 {
            return None;
        }
        let class = |hit: u64, missed: u64, spurious: u64| {
            let union = hit + missed + spurious;
            if union == 0 {
                ClassMetrics {
                    iou: 1.0,
                    dice: 1.0,
                }
            } else {
                ClassMetrics {
                    iou: hit as f64 / union as f64,
                    dice: 2.0 * hit as f64 / (2 * hit + missed + spurious) as f64,
                }
            }
        };
        let catheter = class(self.true_positive, self.false_negative, self.false_positive);
        let background = class(self.true_negative, self.false_positive, self.false_negative);
        Some(SegmentationMetrics {
            pixels,
            accuracy: (self.true_positive + self.true_negative) as f64 / pixels as f64,
            catheter,
            background,
            miou: (catheter.iou + background.iou) / 2.0,
            mdice: (catheter.dice + background.dice) / 2.0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn force_metrics_match_hand_computed_values() {
        // x: targets 1, 2, 3 and predictions 1, 2, 4 -> errors 0, 0, 1.
        // y: exact. z: targets -1, 0, 1 and predictions 0, 0, 0 -> errors 1, 0, 1.
        let mut acc = ForceAccumulator::new();
        acc.push([1.0, 5.0, 0.0].into(), [1.0, 5.0, -1.0].into());
        acc.push([2.0, 6.0, 0.0].into(), [2.0, 6.0, 0.0].into());
        acc.push([4.0, 7.0, 0.0].into(), [3.0, 7.0, 1.0].into());
        let m = acc.finish().unwrap();
        assert_eq!(m.samples, 3);

        let x = m.axes[0];
        assert!(close(x.mae, 1.0 / 3.0));
        assert!(close(x.mse, 1.0 / 3.0));
        assert!(close(x.rmse, (1.0f64 / 3.0).sqrt()));
        // SS_tot = 2, SS_res = 1.
        assert!(close(x.r2.unwrap(), 0.5));
        assert!(close(x.r_over_m.unwrap(), (1.0f64 / 3.0).sqrt() / 3.0));
        assert!(close(x.r_over_range.unwrap(), (1.0f64 / 3.0).sqrt() / 2.0));

        let y = m.axes[1];
        assert_eq!((y.mae, y.mse, y.rmse), (0.0, 0.0, 0.0));
        assert!(close(y.r2.unwrap(), 1.0));

        let z = m.axes[2];
        assert!(close(z.mae, 2.0 / 3.0));
        // Predicting the mean of the target gives R² = 0.
        assert!(close(z.r2.unwrap(), 0.0));
        assert!(close(z.r_over_m.unwrap(), (2.0f64 / 3.0).sqrt()));

        // Pooled over nine values: absolute errors sum to 3, squared errors to 3.
        assert!(close(m.overall.mae, 3.0 / 9.0));
        assert!(close(m.overall.mse, 3.0 / 9.0));
        assert!(close(m.overall.r2.unwrap(), 0.5));
    }

    #[test]
    fn constant_target_gives_undefined_r2_not_nan() {
        let mut acc = ForceAccumulator::new();
        acc.push([0.1, 0.0, 0.2].into(), [0.2, 0.0, 0.2].into());
        acc.push([0.3, 0.0, 0.2].into(), [0.2, 0.0, 0.2].into());
        let m = acc.finish().unwrap();
        assert_eq!(m.axes[0].r2, None);
        assert_eq!(m.axes[0].r_over_range, None);
        // RMSE 0.1 N against max|F| 0.2 N.
        assert!((m.axes[0].r_over_m.unwrap() - 0.5).abs() < 1e-6);
        // An all-zero axis has neither R² nor R/M.
        assert_eq!(m.axes[1].r2, None);
        assert_eq!(m.axes[1].r_over_m, None);
        // Summaries over axes are undefined when an axis is.
        assert_eq!(m.overall.r2, None);
        let json = serde_json::to_string(&m.axes[1]).unwrap();
        assert!(json.contains("\"r2\":null"), "{json}");
    }

    #[test]
    fn empty_sets_have_no_metrics() {
        assert_eq!(ForceAccumulator::new().finish(), None);
        assert_eq!(SegmentationAccumulator::new().finish(), None);
    }

    #[test]
    fn segmentation_metrics_match_hand_computed_values() {
        let mut acc = SegmentationAccumulator::new();
        // TP, FN, FP, TN.
        acc.push(&[0.9, 0.2, 0.7, 0.1], &[1.0, 1.0, 0.0, 0.0])
            .unwrap();
        // Two more TN and one TP.
        acc.push(&[0.0, 0.4, 0.5], &[0.0, 0.0, 1.0]).unwrap();
        let m = acc.finish().unwrap();
        assert_eq!(m.pixels, 7);
        assert!(close(m.accuracy, 5.0 / 7.0));
        // Catheter: TP 2, FN 1, FP 1.
        assert!(close(m.catheter.iou, 2.0 / 4.0));
        assert!(close(m.catheter.dice, 4.0 / 6.0));
        // Background: TN 3, FP 1, FN 1.
        assert!(close(m.background.iou, 3.0 / 5.0));
        assert!(close(m.background.dice, 6.0 / 8.0));
        assert!(close(m.miou, (0.5 + 0.6) / 2.0));
        assert!(close(m.mdice, (4.0 / 6.0 + 0.75) / 2.0));
    }

    #[test]
    fn empty_masks_count_as_perfect_agreement_on_the_absent_class() {
        let mut acc = SegmentationAccumulator::new();
        acc.push(&[0.0; 16], &[0.0; 16]).unwrap();
        let m = acc.finish().unwrap();
        assert_eq!(m.accuracy, 1.0);
        assert_eq!(
            m.catheter,
            ClassMetrics {
                iou: 1.0,
                dice: 1.0
            }
        );
        assert_eq!(
            m.background,
            ClassMetrics {
                iou: 1.0,
                dice: 1.0
            }
        );

        // Predicting catheter where the target is empty: catheter IoU 0, not NaN.
        let mut acc = SegmentationAccumulator::new();
        acc.push(&[1.0, 0.0], &[0.0, 0.0]).unwrap();
        let m = acc.finish().unwrap();
        assert_eq!(
            m.catheter,
            ClassMetrics {
                iou: 0.0,
                dice: 0.0
            }
        );
        assert!(close(m.background.iou, 0.5));
    }

    #[test]
    fn merged_batches_equal_one_pass() {
        let predicted = [0.9, 0.1, 0.6, 0.4, 0.8, 0.3];
        let target = [1.0, 0.0, 0.0, 1.0, 1.0, 0.0];
        let mut whole = SegmentationAccumulator::new();
        whole.push(&predicted, &target).unwrap();
        let mut first = SegmentationAccumulator::new();
        first.push(&predicted[..2], &target[..2]).unwrap();
        let mut second = SegmentationAccumulator::new();
        second.push(&predicted[2..], &target[2..]).unwrap();
        first.merge(&second);
        assert_eq!(first, whole);
    }

    #[test]
    fn mismatched_mask_sizes_are_an_error() {
        let err = SegmentationAccumulator::new()
            .push(&[0.0; 3], &[0.0; 4])
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "predicted mask has 3 pixels but the target has 4"
        );
    }
}
