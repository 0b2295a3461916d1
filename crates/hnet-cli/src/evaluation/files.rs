//! What `hnet eval` writes: the tables as markdown, the predictions file and each pair's
//! predicted masks with their error maps.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use hnet_model::metrics::{AXES, AxisMetrics, PixelOutcome};
use hnet_twin::dataset::{ImageRef, encode_png};
use hnet_twin::reconstruction::physics_force::FOLDS;
use hnet_units::{ImageSize, TipForce};
use serde::{Deserialize, Serialize};

use super::Evaluation;
use crate::physics_check;

/// What the network made of one pair: its force and how well its masks fit, for `hnet report`
/// and the predictions file.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PairPrediction {
    /// The pair's id.
    pub id: String,
    /// True force (N).
    pub truth: TipForce,
    /// Predicted force (N), when the network estimates it.
    pub predicted: Option<TipForce>,
    /// The physics estimate from the network's own masks (the twin's rod fitted to the catheter
    /// they show, N), when the physics check ran and the pair could be fitted.
    #[serde(default)]
    pub physics: Option<TipForce>,
    /// Its fit's standard error per axis, N (a relative measure; see
    /// `hnet_twin::reconstruction::rod_fit::RodFit::force_sd_n`).
    #[serde(default)]
    pub physics_sd: Option<[f32; 3]>,
    /// The correlations of its errors between axes, x-y, x-z, y-z (from the same fit; see
    /// `hnet_twin::reconstruction::rod_fit::RodFit::force_correlation`).
    #[serde(default)]
    pub physics_correlation: Option<[f32; 3]>,
    /// The network's force combined with the physics estimate, N, when a combination was
    /// calibrated.
    #[serde(default)]
    pub combined: Option<TipForce>,
    /// The combined estimate's standard error per axis, N.
    #[serde(default)]
    pub combined_sd: Option<[f32; 3]>,
    /// Half the width of its 90 % interval per axis, N (split-conformal, calibrated with the
    /// combination: [`hnet_twin::reconstruction::physics_force::ForceCombination::interval_90_n`]).
    #[serde(default)]
    pub combined_90: Option<[f32; 3]>,
    /// Catheter IoU of the pair's predicted masks in views A and B, when the network segments
    /// (each mask thresholded as the set's IoU is; 1 where neither mask shows the catheter).
    #[serde(default)]
    pub catheter_iou: Option<[f64; 2]>,
}

/// The predictions file: one line per pair, its true force, the network's, the physics estimate
/// from the network's masks with its fit's standard error and the correlations of its errors
/// between axes (x-y, x-z, y-z), and the two combined with its
/// standard error and the half-width of its 90 % interval (empty where there is none), N; then
/// the catheter IoU of its masks in views A and B (empty without masks), and the physics
/// estimator (`blind` or `oracle`).
pub fn predictions_csv(predictions: &[PairPrediction], estimator: &str) -> String {
    let mut csv = String::from(
        "id,fx,fy,fz,fx_pred,fy_pred,fz_pred,fx_physics,fy_physics,fz_physics,\
         fx_physics_sd,fy_physics_sd,fz_physics_sd,physics_corr_xy,physics_corr_xz,\
         physics_corr_yz,fx_combined,fy_combined,fz_combined,fx_combined_sd,fy_combined_sd,fz_combined_sd,fx_combined_90,fy_combined_90,\
         fz_combined_90,catheter_iou_a,catheter_iou_b,estimator\n",
    );
    let triple = |v: Option<[f32; 3]>| {
        v.map_or_else(|| ",,".to_string(), |[x, y, z]| format!("{x},{y},{z}"))
    };
    for p in predictions {
        let [tx, ty, tz] = p.truth.newtons();
        let _ = writeln!(
            csv,
            "{},{tx},{ty},{tz},{},{},{},{},{},{},{},{},{estimator}",
            p.id,
            triple(p.predicted.map(TipForce::newtons)),
            triple(p.physics.map(TipForce::newtons)),
            triple(p.physics_sd),
            triple(p.physics_correlation),
            triple(p.combined.map(TipForce::newtons)),
            triple(p.combined_sd),
            triple(p.combined_90),
            p.catheter_iou
                .map_or_else(|| ",".to_string(), |[a, b]| format!("{a:.4},{b:.4}"))
        );
    }
    csv
}

/// Colour of each pixel of an error map, RGB.
fn error_rgb(outcome: PixelOutcome) -> [u8; 3] {
    match outcome {
        PixelOutcome::Found => [255, 255, 255],
        PixelOutcome::Missed => [64, 128, 255],
        PixelOutcome::Spurious => [255, 64, 64],
        PixelOutcome::Background => [0, 0, 0],
    }
}

/// Writes pair `id`'s predicted masks (catheter probabilities of views A and B, thresholded at
/// [`hnet_units::mask::MASK_THRESHOLD`]) into `folder` as `<id>_predicted_mask_a.png` and `_b`, at the network's
/// input size (`size`), beside error maps against the label masks `targets` (catheter
/// probabilities, the same size) as `<id>_errors_a.png` and `_b`: white the catheter found, blue
/// missed, red spurious.
pub fn write_predicted_masks(
    folder: &Path,
    id: &str,
    size: ImageSize,
    predicted: &[Vec<f32>; 2],
    targets: &[Vec<f32>; 2],
) -> anyhow::Result<()> {
    for ((view, predicted), target) in ["a", "b"].iter().zip(predicted).zip(targets) {
        let mask = hnet_units::mask::binarize(predicted);
        let errors: Vec<u8> = predicted
            .iter()
            .zip(target)
            .flat_map(|(&p, &t)| error_rgb(PixelOutcome::of(p, t)))
            .collect();
        for (kind, pixels, channels) in [("predicted_mask", &mask, 1), ("errors", &errors, 3)] {
            let path = folder.join(format!("{id}_{kind}_{view}.png"));
            let png = encode_png(ImageRef {
                width: size.width,
                height: size.height,
                channels,
                pixels,
            });
            std::fs::write(&path, png)
                .with_context(|| format!("cannot write '{}'", path.display()))?;
        }
    }
    Ok(())
}

/// `n` quarter turns in words.
fn quarter_turns(n: u8) -> String {
    match n {
        1 => "a quarter turn".into(),
        2 => "a half turn".into(),
        n => format!("{n} quarter turns"),
    }
}

fn number(v: Option<f64>) -> String {
    v.map_or_else(|| "n/a".to_string(), |v| format!("{v:.4}"))
}

/// The two tables as markdown.
pub fn markdown(e: &Evaluation) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} on the {} split of {} ({}, {} parameters){}\n",
        e.architecture,
        e.split,
        e.data.display(),
        e.image_size,
        e.params,
        match e.view_turns {
            0 => String::new(),
            n => format!(", both views turned {} clockwise", quarter_turns(n)),
        }
    );
    let readings = e.mask_averaging.readings();
    if readings > 1 {
        let _ = writeln!(
            s,
            "Masks averaged over {readings} readings of each view (`{}`); the force head reads \
             the views as given.\n",
            e.mask_averaging.name()
        );
    }
    if let Some(entry) = &e.catheter_entry {
        let [a, b] = entry.views_read_turned;
        let _ = write!(
            s,
            "Catheter entry `{}`: of {} pairs, {a} views A and {b} views B read turned (the \
             force head's estimate left out for their pairs)",
            entry.setting, entry.pairs
        );
        if let Some([a, b]) = entry.views_placed_right {
            let _ = write!(
                s,
                "; {a} views A and {b} views B read at their catheter's edge"
            );
        }
        if let Some([a, b]) = entry.view_readings {
            let per_view = (a + b) as f64 / (2 * entry.pairs.max(1)) as f64;
            let _ = write!(s, "; {per_view:.2} readings per view");
        }
        let _ = writeln!(s, "\n");
    }
    if let Some(f) = &e.force {
        let _ = writeln!(s, "Table I: tip force, {} pairs (N, N², N)\n", f.samples);
        let _ = writeln!(s, "| axis | MAE | MSE | RMSE | R² | R/M | RMSE/range |");
        let _ = writeln!(s, "| --- | --- | --- | --- | --- | --- | --- |");
        let row = |s: &mut String, name: &str, m: &AxisMetrics| {
            let _ = writeln!(
                s,
                "| {name} | {:.4} | {:.5} | {:.4} | {} | {} | {} |",
                m.mae,
                m.mse,
                m.rmse,
                number(m.r2),
                number(m.r_over_m),
                number(m.r_over_range)
            );
        };
        for (axis, m) in AXES.iter().zip(&f.axes) {
            row(&mut s, &format!("F{axis}"), m);
        }
        row(&mut s, "mean", &f.overall);
        s.push('\n');
        if let Some(n) = e.pairs_at_other_angles.filter(|&n| n > 0) {
            let _ = writeln!(
                s,
                "{n} of these {} pairs are at C-arm angles the force head was not trained at: \
                 there its force is shown only combined with the physics estimate, never \
                 alone.\n",
                f.samples
            );
        }
    }
    if let (Some(heads), Some(mean)) = (&e.segmentation, &e.segmentation_mean) {
        let _ = writeln!(s, "Table II: segmentation\n");
        let _ = writeln!(
            s,
            "| head | params | accuracy | mIoU | mDice | IoU catheter | Dice catheter |"
        );
        let _ = writeln!(s, "| --- | --- | --- | --- | --- | --- | --- |");
        for (name, m) in [("view A", &heads[0]), ("view B", &heads[1]), ("mean", mean)] {
            let _ = writeln!(
                s,
                "| {name} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
                e.params, m.accuracy, m.miou, m.mdice, m.catheter.iou, m.catheter.dice
            );
        }
    }
    if !e.physics.is_empty() {
        let _ = write!(
            s,
            "\nPhysics estimate: {}{}.\n",
            physics_check::estimator_caption(e.catheter.as_ref()),
            if e.header_error.is_none() {
                String::new()
            } else {
                format!(
                    "; each C-arm's angles read off by up to {}° and its distances by up to {} mm, \
                     plane B's isocentre off by up to {} mm per axis",
                    e.header_error.angle_deg,
                    e.header_error.distance_mm,
                    e.header_error.isocentre_mm
                )
            }
        );
    }
    s.push_str(&physics_check::markdown(&e.physics));
    if let (Some(split), Some(c)) = (
        &e.calibration_split,
        e.physics.iter().find_map(|check| check.combination),
    ) {
        let [x, y, z] = c.network_error_n;
        let data = e
            .calibration_data
            .as_ref()
            .map_or_else(String::new, |d| format!(" of {}", d.display()));
        let _ = match c.stack {
            Some(stack) => writeln!(
                s,
                "\nCombined: a linear stack of both estimates, calibrated on {} pairs of the \
                 {split} split{data}, where {FOLDS}-fold cross-validation read them at mean R² {:.3} \
                 against the per-axis weights' {:.3} (its error {:.4} / {:.4} / {:.4} N).",
                c.pairs,
                stack.cross_validated_r2[0],
                stack.cross_validated_r2[1],
                stack.error_n[0],
                stack.error_n[1],
                stack.error_n[2],
            ),
            None => writeln!(
                s,
                "\nCombined: each axis weighted by the inverse of its error variance, calibrated \
                 on {} pairs of the {split} split{data} (network error {x:.4} / {y:.4} / {z:.4} \
                 N, the fit's standard error times {:.2}).",
                c.pairs, c.physics_sd_scale
            ),
        };
    }
    s
}
