//! `hnet eval --record`: what the evaluation measured, written into the weights file's facts
//! ([`hnet_twin::model_facts`]) for the page and `hnet trace` to read.

use std::path::Path;

use anyhow::Context;
use hnet_model::metrics::ForceMetrics;
use hnet_model::predictor::Predictor;
use hnet_twin::dataset::Dataset;
use hnet_twin::model_facts::{
    ForceDomain, MeasuredCombination, MeasuredForce, ModelFacts, recorded_name,
};
use hnet_twin::reconstruction::MaskOrigin;
use hnet_units::TipForce;

use super::{EvalArgs, Evaluation, PairPrediction};

/// Writes what `evaluation` measured into the facts of the weights file at `path` (and, with
/// `--trained-on`, the data its force was trained on), rewriting it atomically.
pub(super) fn record_facts(
    model: &Predictor,
    evaluation: &Evaluation,
    predictions: &[PairPrediction],
    args: &EvalArgs,
    path: &Path,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        evaluation.catheter_entry.is_none(),
        "--record measures the force of views read as they are: leave --catheter-entry out"
    );
    let force = evaluation.force.with_context(|| {
        format!(
            "--record: a `{}` network estimates no force to record",
            model.spec.name()
        )
    })?;
    let mut facts = ModelFacts::read(&model.header.provenance)
        .with_context(|| format!("weights file '{}'", path.display()))?;
    let mse = |m: &ForceMetrics| m.axes.map(|a| a.mse as f32);
    let combined = evaluation
        .physics
        .iter()
        .find(|p| p.masks == MaskOrigin::Predicted)
        .and_then(|p| {
            Some((
                p.combination?,
                p.combined_force.as_ref()?,
                p.combined_coverage_90,
            ))
        })
        .map(|(combination, metrics, coverage)| MeasuredCombination {
            combination,
            calibration_data: format!(
                "{} ({})",
                recorded_name(
                    evaluation
                        .calibration_data
                        .as_deref()
                        .unwrap_or(&evaluation.data)
                ),
                evaluation.calibration_split.as_deref().unwrap_or("val")
            ),
            pairs: metrics.samples as usize,
            mse_n2: mse(metrics),
            coverage_90: coverage.map(|c| c.map(|v| v as f32)),
        });
    if combined.is_none()
        && let Some(recorded) = facts.measured.as_ref().filter(|m| m.combined.is_some())
    {
        anyhow::bail!(
            "--record: this evaluation calibrated no combined estimate (a simulated set and the \
             physics estimate are needed), and recording it would erase the calibration the \
             file holds (recorded by `{}`)",
            recorded.command
        );
    }
    // How often the force head's own interval held on the evaluated pairs.
    let head_coverage_90 = combined.as_ref().map(|c| {
        let half = c.combination.head_interval_90_n();
        let heads: Vec<(TipForce, TipForce)> = predictions
            .iter()
            .filter_map(|p| Some((p.truth, p.predicted?)))
            .collect();
        std::array::from_fn(|axis| {
            let held = heads
                .iter()
                .filter(|(truth, head)| (head[axis] - truth[axis]).abs() <= half[axis])
                .count();
            held as f32 / heads.len().max(1) as f32
        })
    });
    if let Some([x, y, z]) = head_coverage_90 {
        eprintln!(
            "the force head's own 90 % interval held {:.0} / {:.0} / {:.0} % of the true forces",
            x * 100.0,
            y * 100.0,
            z * 100.0
        );
    }
    facts.measured = Some(MeasuredForce {
        data: recorded_name(&evaluation.data),
        split: evaluation.split.clone(),
        pairs: force.samples as usize,
        estimator: evaluation.estimator.clone(),
        mask_averaging: evaluation.mask_averaging,
        head_mse_n2: mse(&force),
        head_coverage_90,
        combined,
        command: crate::command_line(),
    });
    if let Some(trained_on) = &args.trained_on {
        let dataset = Dataset::open(trained_on)?;
        facts.force_domain = Some(
            ForceDomain::of_twin_source(&recorded_name(trained_on), &dataset.header.source)
                .with_context(|| {
                    format!(
                        "--trained-on '{}': not a dataset of the twin (its header names no twin \
                         settings)",
                        trained_on.display()
                    )
                })?,
        );
    }
    let mut provenance = model.header.provenance.clone();
    facts.write(&mut provenance);
    let bytes = model
        .net
        .to_weights_bytes(&model.spec, &provenance)
        .with_context(|| format!("weights file '{}'", path.display()))?;
    hnet_twin::dataset::files::write_atomically(path, &bytes)
        .with_context(|| format!("cannot write '{}'", path.display()))?;
    eprintln!("facts recorded in {}", path.display());
    Ok(())
}
