//! A linear stack of the force head and the physics estimate, for calibration sets on which it
//! predicts better than the per-axis weights.
//!
//! Per-axis inverse-variance weights cannot undo an error that mixes axes. On the paper's bench
//! the blind fit reads an (Fx, Fz) mixture (its Fx and Fz errors correlate at 1.00), and a least
//! squares map from both estimates' six components to each axis reads those pairs at R² 0.93
//! against the weights' 0.89, while on the clinical bench, whose physics errors differ from pair
//! to pair with the fit's standard error, it loses 0.03
//! (docs/log/2026-12-05-weighing-the-combination.md). So
//! [`ForceCombination::calibrate`](super::ForceCombination::calibrate) chooses between the two by
//! cross-validation on its calibration pairs, and the stack is kept only where it wins.

use hnet_units::TipForce;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::{CalibrationPair, ForceCombination, conformal_quantile};

/// Fewest calibration pairs a stack is fitted on: 7 coefficients per axis want many more pairs
/// than that, and each of [`FOLDS`] folds is predicted by a fit to the others.
pub const MIN_STACK_PAIRS: usize = 200;

/// Folds of the cross-validation that chooses between the per-axis weights and the stack.
pub const FOLDS: usize = 5;

/// How much higher the stack's cross-validated mean R² must be than the per-axis weights' for it
/// to be kept: a margin, so that sampling noise does not swap the rule.
pub const MIN_STACK_GAIN: f64 = 0.01;

/// The tip force as a linear function of both estimates, per axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LinearStack {
    /// For each axis (x, y, z): the coefficients of the network's Fx, Fy, Fz, the physics
    /// estimate's Fx, Fy, Fz (dimensionless) and a constant (N).
    pub coefficients: [[f32; 7]; 3],
    /// Its root mean square error per axis on the calibration pairs, each predicted by a stack
    /// fitted to the other folds, N.
    pub error_n: [f32; 3],
    /// Mean R² over the axes of the stack and of the per-axis weights under that
    /// cross-validation, which chose the stack.
    pub cross_validated_r2: [f32; 2],
}

impl LinearStack {
    /// The force of a pair from the network's `network_n` and the physics estimate `physics_n`,
    /// N.
    pub fn apply(&self, network_n: TipForce, physics_n: TipForce) -> TipForce {
        let inputs = features(network_n, physics_n);
        TipForce::from_newtons(std::array::from_fn(|axis| {
            let c = &self.coefficients[axis];
            (0..7).map(|k| f64::from(c[k]) * inputs[k]).sum::<f64>() as f32
        }))
    }
}

fn features(network_n: TipForce, physics_n: TipForce) -> [f64; 7] {
    let [a, b, c] = network_n.newtons().map(f64::from);
    let [d, e, f] = physics_n.newtons().map(f64::from);
    [a, b, c, d, e, f, 1.0]
}

/// Least squares coefficients on `pairs`, or `None` for a singular design.
fn fit(pairs: &[CalibrationPair]) -> Option<[[f32; 7]; 3]> {
    let x = DMatrix::from_fn(pairs.len(), 7, |i, k| {
        features(pairs[i].network_n, pairs[i].physics_n)[k]
    });
    let y = DMatrix::from_fn(pairs.len(), 3, |i, axis| {
        f64::from(pairs[i].truth_n.newtons()[axis])
    });
    let solution = x.svd(true, true).solve(&y, 1e-12).ok()?;
    let coefficients: [[f32; 7]; 3] =
        std::array::from_fn(|axis| std::array::from_fn(|k| solution[(k, axis)] as f32));
    coefficients
        .iter()
        .flatten()
        .all(|c| c.is_finite())
        .then_some(coefficients)
}

/// Mean over the axes of `1 − SSE/SST` for `estimates` of `pairs`' true forces; `None` where an
/// axis's true force does not vary (R² means nothing there).
fn mean_r2(pairs: &[CalibrationPair], estimates: &[TipForce]) -> Option<f64> {
    let r2: Option<Vec<f64>> = (0..3)
        .map(|axis| {
            let truth: Vec<f64> = pairs
                .iter()
                .map(|p| f64::from(p.truth_n.newtons()[axis]))
                .collect();
            let mean = truth.iter().sum::<f64>() / truth.len() as f64;
            let total: f64 = truth.iter().map(|t| (t - mean).powi(2)).sum();
            let error: f64 = truth
                .iter()
                .zip(estimates)
                .map(|(t, e)| (t - f64::from(e.newtons()[axis])).powi(2))
                .sum();
            (total > 1e-12).then(|| 1.0 - error / total)
        })
        .collect();
    r2.map(|r2| r2.iter().sum::<f64>() / 3.0)
}

/// The stack for `pairs` when, under [`FOLDS`]-fold cross-validation, it predicts them better
/// than the per-axis weights by at least [`MIN_STACK_GAIN`] of mean R²; with its 90 % interval's
/// half-width per axis (N, split-conformal over the cross-validated errors). `None` with fewer
/// than [`MIN_STACK_PAIRS`] pairs, or where the weights do as well.
pub(super) fn choose(pairs: &[CalibrationPair]) -> Option<(LinearStack, [f32; 3])> {
    if pairs.len() < MIN_STACK_PAIRS {
        return None;
    }
    let mut by_stack = vec![TipForce::ZERO; pairs.len()];
    let mut by_weights = vec![TipForce::ZERO; pairs.len()];
    for fold in 0..FOLDS {
        let rest: Vec<CalibrationPair> = pairs
            .iter()
            .enumerate()
            .filter(|(i, _)| i % FOLDS != fold)
            .map(|(_, p)| *p)
            .collect();
        let stack = LinearStack {
            coefficients: fit(&rest)?,
            error_n: [0.0; 3],
            cross_validated_r2: [0.0; 2],
        };
        let weights = ForceCombination::per_axis_weights(&rest)?;
        for (i, p) in pairs.iter().enumerate().filter(|(i, _)| i % FOLDS == fold) {
            by_stack[i] = stack.apply(p.network_n, p.physics_n);
            by_weights[i] = weights
                .combine_with_sd(p.network_n, p.physics_n, Some(p.physics_sd_n))
                .0;
        }
    }
    let (stack_r2, weights_r2) = (mean_r2(pairs, &by_stack)?, mean_r2(pairs, &by_weights)?);
    if stack_r2 < weights_r2 + MIN_STACK_GAIN {
        return None;
    }
    let residuals: [Vec<f64>; 3] = std::array::from_fn(|axis| {
        pairs
            .iter()
            .zip(&by_stack)
            .map(|(p, e)| f64::from(e.newtons()[axis] - p.truth_n.newtons()[axis]).abs())
            .collect()
    });
    let error_n = std::array::from_fn(|axis| {
        let r = &residuals[axis];
        (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt() as f32
    });
    let mut interval = [0.0f32; 3];
    for (axis, mut r) in residuals.into_iter().enumerate() {
        interval[axis] = conformal_quantile(&mut r, 0.9)? as f32;
    }
    Some((
        LinearStack {
            coefficients: fit(pairs)?,
            error_n,
            cross_validated_r2: [stack_r2 as f32, weights_r2 as f32],
        },
        interval,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pairs whose physics estimate reads Fx mixed with Fz (as the paper's bench does), the
    /// network off by noise; a deterministic generator.
    fn mixed_pairs(count: usize, seed: u64) -> Vec<CalibrationPair> {
        let mut state = seed;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f32 / (1u64 << 53) as f32 - 0.5
        };
        (0..count)
            .map(|_| {
                let truth_n =
                    TipForce::new(0.1 * uniform(), 0.05 * uniform(), -0.2 + 0.2 * uniform());
                let [x, y, z] = truth_n.newtons();
                CalibrationPair {
                    truth_n,
                    network_n: truth_n.map(|t| t + 0.06 * uniform()),
                    physics_n: TipForce::new(
                        0.8 * x - 0.4 * z + 0.01 * uniform(),
                        y + 0.01 * uniform(),
                        z + 0.01 * uniform(),
                    ),
                    physics_sd_n: [0.01; 3],
                }
            })
            .collect()
    }

    #[test]
    fn a_stack_is_kept_only_where_it_predicts_better() {
        let calibration = mixed_pairs(400, 3);
        let c = ForceCombination::calibrate(&calibration).unwrap();
        let stack = c.stack.expect("the weights cannot undo the mixing");
        assert!(stack.cross_validated_r2[0] > stack.cross_validated_r2[1] + MIN_STACK_GAIN as f32);
        // It undoes it on fresh pairs, and its interval covers about 90 % of them.
        let fresh = mixed_pairs(2000, 11);
        for axis in 0..3 {
            let covered = fresh
                .iter()
                .filter(|p| {
                    let e = c.estimate(p.network_n, Some((p.physics_n, Some(p.physics_sd_n))));
                    (e.force_n[axis] - p.truth_n[axis]).abs() <= e.interval_90_n.unwrap()[axis]
                })
                .count() as f64
                / fresh.len() as f64;
            assert!((0.86..=0.94).contains(&covered), "axis {axis}: {covered}");
        }
        let p = &fresh[0];
        let off = (stack.apply(p.network_n, p.physics_n) - p.truth_n).max_abs();
        assert!(off < 0.03, "{off}");
        // Unmixed, and a physics estimate good or useless from pair to pair as its fit's standard
        // error says (the clinical bench): the per-axis weights follow that and stay. Too few
        // pairs, and no stack is tried.
        let mut noise = mixed_pairs(calibration.len(), 5)
            .into_iter()
            .map(|q| q.network_n - q.truth_n);
        let plain: Vec<CalibrationPair> = calibration
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let sd = if i % 2 == 0 { 0.002 } else { 0.2 };
                // Independent noise per axis (another draw's network errors, ±0.03 N), scaled
                // to this pair's standard error.
                let n = noise.next().unwrap();
                let physics_n = TipForce::from_newtons(std::array::from_fn(|axis| {
                    p.truth_n[axis] + sd / 0.03 * n[axis]
                }));
                CalibrationPair {
                    physics_n,
                    physics_sd_n: [sd; 3],
                    ..*p
                }
            })
            .collect();
        assert_eq!(ForceCombination::calibrate(&plain).unwrap().stack, None);
        assert_eq!(
            ForceCombination::calibrate(&calibration[..MIN_STACK_PAIRS - 1])
                .unwrap()
                .stack,
            None
        );
    }
}
