//! How the force head's estimate and the physics estimate are weighed into the one tip force the
//! page, `hnet trace` and `hnet eval` report, with its split-conformal 90 % interval
//! ([`ForceCombination`]), and which estimate a figure is ([`EstimateKind`]).

use hnet_units::TipForce;
use serde::{Deserialize, Serialize};

use super::stack::{self, LinearStack};

/// Below this many calibration pairs no combination is calibrated.
pub const MIN_CALIBRATION_PAIRS: usize = 10;

/// Half the width of a two-sided 90 % normal interval, in standard deviations.
pub const INTERVAL_90_Z: f64 = 1.644_853_6;

/// The median of `|z|` for a standard normal `z`, which turns a median absolute deviation into a
/// standard deviation.
const NORMAL_MEDIAN_ABS: f64 = 0.674_489_75;

/// How one network's tip force and the physics estimate from its own masks are weighed against
/// each other: on each axis, each by the inverse of its error variance. The network's error is
/// one number per axis; the physics estimate's is the rod fit's own standard error
/// ([`crate::reconstruction::rod_fit::RodFit::force_sd_n`]) times [`Self::physics_sd_scale`], so it differs from
/// pair to pair with how much the reconstructed shape says about the force.
///
/// Both are measured on calibration pairs the estimates are not evaluated on
/// ([`Self::calibrate`]; `hnet eval` uses the split next to the one it evaluates). Where
/// cross-validation on those pairs says a linear stack of both estimates predicts them better
/// (an error that mixes axes, which weights per axis cannot undo), the stack replaces the weights
/// ([`Self::stack`]).
/// Inverse-variance weights assume the two errors independent; their Fz errors correlate at
/// -0.01 to 0.15 on the sets measured (docs/results.md, "The combined estimate"), so the
/// combined error is a little larger than the weights assume.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceCombination {
    /// The network's error per axis (x, y, z), N: its root mean square error on the calibration
    /// pairs.
    pub network_error_n: [f32; 3],
    /// The physics estimate's error per unit of the fit's standard error, dimensionless: the
    /// median of `|error / standard error|` over the calibration pairs' three axes, divided by
    /// a normal's median `|z|` (0.6745). Above 1 because the centreline's points are not
    /// independent (about 3 on the bench).
    pub physics_sd_scale: f32,
    /// Calibration pairs it was measured on.
    pub pairs: usize,
    /// Half the width of the 90 % interval per axis, in combined standard errors
    /// ([`Self::combine_with_sd`]): split-conformal, the `⌈0.9·(n + 1)⌉`-th smallest of the
    /// calibration pairs' `|combined − true| / standard error`, so that on pairs like them the
    /// interval holds the true force at least 90 % of the time whatever the errors'
    /// distribution or correlation. [`INTERVAL_90_Z`] (a normal's) for combinations stored
    /// before it was measured.
    #[serde(default = "normal_interval_90")]
    pub interval_90_sd: [f32; 3],
    /// Half the width of the network's own 90 % interval per axis, N, for a pair without a
    /// physics estimate: split-conformal, the `⌈0.9·(n + 1)⌉`-th smallest `|network − true|` of
    /// the calibration pairs. `None` for combinations stored before it was measured, which
    /// read [`INTERVAL_90_Z`] times [`Self::network_error_n`] instead
    /// ([`Self::head_interval_90_n`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network_interval_90_n: Option<[f32; 3]>,
    /// A linear stack of both estimates that replaces the per-axis weights, where it predicted
    /// the calibration pairs better under cross-validation ([`LinearStack`]); `None` where the
    /// weights did as well, and for combinations stored before it was tried.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stack: Option<LinearStack>,
}

/// Which of the product's tip-force estimates a figure is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EstimateKind {
    /// The network's force head alone.
    Head,
    /// The network's force combined with the physics estimate from its own masks
    /// ([`ForceCombination::combine_with_sd`]).
    Combined,
}

impl EstimateKind {
    /// Its name in tables, traces and on the page.
    pub fn name(self) -> &'static str {
        match self {
            Self::Head => "H-Net force head",
            Self::Combined => "Combined",
        }
    }
}

/// Why the force head gives no estimate on its own for a pair unlike those it was trained on as
/// `departures` say (C-arm angles; for a twin pair, its catheter and pose): what the page, its
/// cine trace and `hnet trace` show in its place.
pub fn head_withheld(departures: &[String]) -> String {
    format!(
        "no physics estimate from H-Net's masks to combine it with, and the force head alone is \
         withheld for pairs unlike those it was trained on ({}), where its R² was below zero",
        departures.join("; ")
    )
}

/// A tip-force estimate with its 90 % interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TipForceEstimate {
    /// `(Fx, Fy, Fz)`, N.
    pub force_n: TipForce,
    /// Half the width of the 90 % interval per axis, N: the true force lies within
    /// `force_n ± interval_90_n` on each axis for 90 % of pairs like the calibration pairs.
    /// `None` for weights that carry no calibration ([`TipForceEstimate::uncalibrated`]).
    pub interval_90_n: Option<[f32; 3]>,
    /// Which estimate it is.
    pub kind: EstimateKind,
}

impl TipForceEstimate {
    /// The network's force `force_n` (N) from weights that carry no calibration: no interval.
    pub fn uncalibrated(force_n: TipForce) -> Self {
        Self {
            force_n,
            interval_90_n: None,
            kind: EstimateKind::Head,
        }
    }

    /// The range of the magnitude |F| over the box of the per-axis intervals, N: `(lowest,
    /// highest)`, when there is an interval. (Each axis holds the true force 90 % of the time,
    /// so the box holds it less often than that, and the range of |F| is wider than a 90 %
    /// interval of |F| would be.)
    pub fn magnitude_range_n(&self) -> Option<(f32, f32)> {
        let interval = self.interval_90_n?;
        let mut low = 0.0f32;
        let mut high = 0.0f32;
        for (f, h) in self.force_n.newtons().iter().zip(interval) {
            let (a, b) = (f - h, f + h);
            let nearest = if a <= 0.0 && b >= 0.0 {
                0.0
            } else {
                a.abs().min(b.abs())
            };
            low += nearest * nearest;
            high += a.abs().max(b.abs()).powi(2);
        }
        Some((low.sqrt(), high.sqrt()))
    }
}

fn normal_interval_90() -> [f32; 3] {
    [INTERVAL_90_Z as f32; 3]
}

/// One calibration pair: the true force, the network's and the physics estimate with its fit's
/// standard error, N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationPair {
    /// True tip force, N.
    pub truth_n: TipForce,
    /// The network's estimate, N.
    pub network_n: TipForce,
    /// The physics estimate from the network's masks, N.
    pub physics_n: TipForce,
    /// Its fit's standard error per axis, N.
    pub physics_sd_n: [f32; 3],
}

impl ForceCombination {
    /// Measures both errors on `pairs`, and keeps a [`LinearStack`] instead of the per-axis
    /// weights where cross-validation on them says it predicts better; `None` with fewer than
    /// [`MIN_CALIBRATION_PAIRS`] pairs (or no usable standard error).
    pub fn calibrate(pairs: &[CalibrationPair]) -> Option<Self> {
        let mut combination = Self::per_axis_weights(pairs)?;
        let both: Vec<(TipForce, TipForce)> =
            pairs.iter().map(|p| (p.truth_n, p.network_n)).collect();
        combination.calibrate_head_interval(&both);
        if let Some((stack, interval_90_n)) = stack::choose(pairs) {
            // Its interval in units of its (cross-validated) error, which `combine_with_sd`
            // answers as the standard error of a stacked estimate.
            combination.interval_90_sd =
                std::array::from_fn(|axis| interval_90_n[axis] / stack.error_n[axis].max(1e-9));
            combination.stack = Some(stack);
            return Some(combination);
        }
        // Split-conformal: the calibration pairs' normalised errors of the combined estimate.
        let scores: [Vec<f64>; 3] = std::array::from_fn(|axis| {
            pairs
                .iter()
                .filter_map(|p| {
                    let (force, sd) =
                        combination.combine_with_sd(p.network_n, p.physics_n, Some(p.physics_sd_n));
                    let sd = f64::from(sd[axis]);
                    let off = f64::from((force[axis] - p.truth_n[axis]).abs());
                    (sd > 0.0).then_some(off / sd).filter(|s| s.is_finite())
                })
                .collect()
        });
        for (axis, mut scores) in scores.into_iter().enumerate() {
            if let Some(q) = conformal_quantile(&mut scores, 0.9) {
                combination.interval_90_sd[axis] = q as f32;
            }
        }
        Some(combination)
    }

    /// The per-axis weights alone, measured on `pairs` (the network's RMSE and the physics
    /// estimate's scale), with a normal's interval.
    pub(super) fn per_axis_weights(pairs: &[CalibrationPair]) -> Option<Self> {
        if pairs.len() < MIN_CALIBRATION_PAIRS {
            return None;
        }
        let network_error_n = std::array::from_fn(|axis| {
            let mse = pairs
                .iter()
                .map(|p| f64::from(p.network_n[axis] - p.truth_n[axis]).powi(2))
                .sum::<f64>()
                / pairs.len() as f64;
            mse.sqrt() as f32
        });
        let mut z: Vec<f64> = pairs
            .iter()
            .flat_map(|p| {
                (0..3).filter_map(move |axis| {
                    let sd = f64::from(p.physics_sd_n[axis]);
                    (sd > 0.0 && sd.is_finite())
                        .then(|| f64::from(p.physics_n[axis] - p.truth_n[axis]).abs() / sd)
                })
            })
            .filter(|z| z.is_finite())
            .collect();
        if z.len() < MIN_CALIBRATION_PAIRS {
            return None;
        }
        let middle = z.len() / 2;
        let (_, median, _) = z.select_nth_unstable_by(middle, f64::total_cmp);
        Some(Self {
            network_error_n,
            physics_sd_scale: (*median / NORMAL_MEDIAN_ABS) as f32,
            pairs: pairs.len(),
            interval_90_sd: normal_interval_90(),
            network_interval_90_n: None,
            stack: None,
        })
    }

    /// Measures the network's own 90 % interval ([`Self::network_interval_90_n`]) on `pairs` of
    /// (true force, the network's), N. [`Self::calibrate`] measures it on its pairs, which the rod
    /// fitted; the interval is for pairs without a physics estimate, so `hnet eval` measures it
    /// again on every calibration pair with a network force, fitted or not.
    pub fn calibrate_head_interval(&mut self, pairs: &[(TipForce, TipForce)]) {
        let mut scores: [Vec<f64>; 3] = std::array::from_fn(|axis| {
            pairs
                .iter()
                .map(|(truth, network)| f64::from((network[axis] - truth[axis]).abs()))
                .filter(|s| s.is_finite())
                .collect()
        });
        let head: Option<Vec<f32>> = scores
            .iter_mut()
            .map(|scores| conformal_quantile(scores, 0.9).map(|q| q as f32))
            .collect();
        if let Some(h) = head {
            self.network_interval_90_n = Some([h[0], h[1], h[2]]);
        }
    }

    /// Half the width of the network's own 90 % interval per axis, N
    /// ([`Self::network_interval_90_n`], or a normal's from its error where that was not
    /// measured).
    pub fn head_interval_90_n(&self) -> [f32; 3] {
        self.network_interval_90_n
            .unwrap_or(self.network_error_n.map(|e| e * INTERVAL_90_Z as f32))
    }

    /// The estimate of a pair: combined with the physics estimate `physics` (its force and its
    /// fit's standard error, N) where there is one with a standard error, else the network's
    /// `network_n` alone (the combination's intervals were calibrated on fits with a standard
    /// error); each with its 90 % interval. The one rule of `hnet trace` and the page.
    pub fn estimate(
        &self,
        network_n: TipForce,
        physics: Option<(TipForce, Option<[f32; 3]>)>,
    ) -> TipForceEstimate {
        match physics {
            Some((physics_n, Some(physics_sd_n))) => {
                let (force_n, sd) = self.combine_with_sd(network_n, physics_n, Some(physics_sd_n));
                TipForceEstimate {
                    force_n,
                    interval_90_n: Some(self.interval_90_n(sd)),
                    kind: EstimateKind::Combined,
                }
            }
            Some((_, None)) | None => TipForceEstimate {
                force_n: network_n,
                interval_90_n: Some(self.head_interval_90_n()),
                kind: EstimateKind::Head,
            },
        }
    }

    /// [`Self::estimate`] for a pair unlike those the force head was trained on as `departures`
    /// say (its views' C-arm angles, [`crate::model_facts::ForceDomain::view_departures`]; for a
    /// twin pair also its catheter and pose,
    /// [`crate::simulator::scene::SceneSampling::catheter_departures`]; empty for a pair like
    /// them): where that would be the force head alone, no estimate, and
    /// why ([`head_withheld`]). The head learnt the force from how its training catheter looks
    /// in its trained views; at the page's other C-arm angles its R² was below zero, and so it
    /// was with other catheters and poses (docs/results.md, `off-bench` and `varied`). Combined
    /// with the physics estimate it stays, weighed by the calibration. The one rule of the
    /// page's force panel, its cine trace and `hnet trace`.
    pub fn estimate_at(
        &self,
        network_n: TipForce,
        physics: Option<(TipForce, Option<[f32; 3]>)>,
        departures: &[String],
    ) -> Result<TipForceEstimate, String> {
        let estimate = self.estimate(network_n, physics);
        if estimate.kind == EstimateKind::Head && !departures.is_empty() {
            return Err(head_withheld(departures));
        }
        Ok(estimate)
    }

    /// Half the width of the 90 % interval per axis, N, for the combined standard error `sd_n`.
    pub fn interval_90_n(&self, sd_n: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|axis| sd_n[axis] * self.interval_90_sd[axis])
    }

    /// The combined tip force, N: per axis, `(n/σn² + p/σp²) / (1/σn² + 1/σp²)` for the
    /// network's `network_n` and the physics estimate `physics_n` (its fit's standard error
    /// `physics_sd_n`, N, scaled). Without a standard error (a singular fit) both weigh the
    /// same.
    pub fn combine(
        &self,
        network_n: TipForce,
        physics_n: TipForce,
        physics_sd_n: Option<[f32; 3]>,
    ) -> TipForce {
        self.combine_with_sd(network_n, physics_n, physics_sd_n).0
    }

    /// [`Self::combine`] with the combined estimate's standard error per axis, N:
    /// `1/sqrt(1/σn² + 1/σp²)` (both errors taken as independent; the 90 % interval is
    /// [`Self::interval_90_sd`] of them either side, [`Self::interval_90_n`]). With a
    /// [`Self::stack`], its estimate and its cross-validated error instead.
    pub fn combine_with_sd(
        &self,
        network_n: TipForce,
        physics_n: TipForce,
        physics_sd_n: Option<[f32; 3]>,
    ) -> (TipForce, [f32; 3]) {
        if let Some(stack) = &self.stack {
            return (stack.apply(network_n, physics_n), stack.error_n);
        }
        let mut sd = [0.0f32; 3];
        let force = std::array::from_fn(|axis| {
            let network_var = f64::from(self.network_error_n[axis]).powi(2);
            let physics_var = physics_sd_n
                .map(|sd| f64::from(sd[axis] * self.physics_sd_scale).powi(2))
                .filter(|v| v.is_finite())
                .unwrap_or(network_var);
            // The physics estimate's weight: 1 when it is exact, 0 when it says nothing.
            let w = if network_var + physics_var > 0.0 {
                network_var / (network_var + physics_var)
            } else {
                0.5
            };
            sd[axis] = if network_var > 0.0 && physics_var > 0.0 {
                (1.0 / (1.0 / network_var + 1.0 / physics_var)).sqrt() as f32
            } else {
                0.0
            };
            (w * f64::from(physics_n[axis]) + (1.0 - w) * f64::from(network_n[axis])) as f32
        });
        (TipForce::from_newtons(force), sd)
    }
}

/// The split-conformal quantile of `scores` at `level`: the `⌈level·(n + 1)⌉`-th smallest of
/// the `n` scores (the largest when that rank exceeds `n`), so that a new score exchangeable with
/// them is at most it with probability at least `level`. `None` without scores.
pub fn conformal_quantile(scores: &mut [f64], level: f64) -> Option<f64> {
    if scores.is_empty() {
        return None;
    }
    let n = scores.len();
    let rank = ((level * (n + 1) as f64).ceil() as usize).clamp(1, n);
    let (_, q, _) = scores.select_nth_unstable_by(rank - 1, f64::total_cmp);
    Some(*q)
}
