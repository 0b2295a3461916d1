//! `hnet eval`'s physics estimate: the twin's rod fitted to the catheter in the dataset's own
//! masks and in the network's, and the combination of the network's force with it.

use burn::tensor::Device;
use hnet_model::predictor::{PairOutput, Predictor};
use hnet_twin::dataset::simulate::SampleRecord;
use hnet_twin::dataset::{Dataset, Split};
use hnet_twin::reconstruction::MaskOrigin;
use hnet_twin::reconstruction::centreline::Mask;
use hnet_twin::reconstruction::physics_force::{ForceCombination, MIN_CALIBRATION_PAIRS};
use hnet_units::TipForce;

use crate::data::{StereoItem, StereoSplit};
use crate::network::predict;
use crate::physics_check::{self, Estimator, PairToCheck, PhysicsEvaluation};

/// Calibrates the combination of the network's force and the physics estimate from its own masks
/// ([`ForceCombination::calibrate`]) on `split` of `dataset`; `None` (with a note) where that
/// split has too few simulated pairs.
pub(super) fn calibrate_combination(
    model: &Predictor,
    dataset: &Dataset,
    split: Split,
    device: &Device,
    batch_size: usize,
    estimator: &Estimator,
) -> anyhow::Result<Option<(Split, ForceCombination)>> {
    let pairs = StereoSplit::load(dataset, split, model.image_size, None)?;
    let ids: Vec<&str> = pairs.items.iter().map(|item| &*item.id).collect();
    let records = match physics_check::read_records(dataset, &ids) {
        Some(records) if !records.is_empty() => records,
        _ => {
            eprintln!(
                "no combined force: the {} split of {} has no simulated pairs to calibrate it on",
                split.name(),
                dataset.root.display()
            );
            return Ok(None);
        }
    };
    let mut predicted = Vec::with_capacity(pairs.items.len());
    predict(
        model,
        &pairs.items,
        batch_size,
        device,
        |_, masks, force| {
            predicted.push(PairOutput { masks, force });
        },
    )?;
    let to_check = network_pairs(model, &pairs.items, &predicted);
    let check = physics_check::check(
        MaskOrigin::Predicted,
        model.image_size,
        &to_check,
        &records,
        estimator,
        None,
    );
    let mut combination = ForceCombination::calibrate(&check.calibration_pairs(&to_check));
    // The force head's own interval is for pairs without a physics estimate: measured on every
    // calibration pair with a network force, fitted or not.
    if let Some(c) = combination.as_mut() {
        let heads: Vec<(TipForce, TipForce)> = to_check
            .iter()
            .filter_map(|p| Some((p.truth_n, p.network_n?)))
            .collect();
        c.calibrate_head_interval(&heads);
    }
    if combination.is_none() {
        eprintln!(
            "no combined force: {} of the {} pairs of the {} split of {} were fitted, at least {} \
             needed to calibrate it",
            check.fitted,
            check.pairs,
            split.name(),
            dataset.root.display(),
            MIN_CALIBRATION_PAIRS
        );
    }
    Ok(combination.map(|c| (split, c)))
}

/// The pairs to check from the network's own masks (every item has them: the network segments).
fn network_pairs<'a>(
    model: &Predictor,
    items: &[StereoItem],
    predicted: &'a [PairOutput],
) -> Vec<PairToCheck<'a>> {
    let net = model.image_size;
    predicted
        .iter()
        .zip(items)
        .filter_map(|(p, item)| {
            let [a, b] = p.masks.as_ref()?;
            Some(PairToCheck {
                truth_n: item.force_n,
                network_n: p.force,
                masks: [a, b].map(|m| Mask::soft(net.width, net.height, m)),
            })
        })
        .collect()
}

/// The physics check of every pair: from the dataset's own masks at its own size, and from the
/// network's masks (at its input size) when it segments.
pub(super) fn physics_checks(
    dataset: &Dataset,
    split: Split,
    model: &Predictor,
    items: &[StereoItem],
    predicted: &[PairOutput],
    records: &[SampleRecord],
    (estimator, combination): (&Estimator, Option<&ForceCombination>),
) -> anyhow::Result<Vec<PhysicsEvaluation>> {
    use rayon::prelude::*;
    let rows: Vec<_> = dataset.split(split).collect();
    let true_masks = rows
        .par_iter()
        .map(|row| dataset.load_pair(row, None))
        .collect::<Result<Vec<_>, _>>()?;
    let size = dataset.header.image_size;
    fn pair<'a>(
        items: &[StereoItem],
        predicted: &[PairOutput],
        i: usize,
        masks: [Mask<'a>; 2],
    ) -> PairToCheck<'a> {
        PairToCheck {
            truth_n: items[i].force_n,
            network_n: predicted[i].force,
            masks,
        }
    }
    let from_truth: Vec<_> = true_masks
        .iter()
        .enumerate()
        .map(|(i, p)| {
            pair(
                items,
                predicted,
                i,
                [&p.mask_a, &p.mask_b].map(|m| Mask::soft(size.width, size.height, m)),
            )
        })
        .collect();
    let mut checks = vec![physics_check::check(
        MaskOrigin::Labels,
        size,
        &from_truth,
        records,
        estimator,
        None,
    )];
    if predicted.iter().all(|p| p.masks.is_some()) {
        checks.push(physics_check::check(
            MaskOrigin::Predicted,
            model.image_size,
            &network_pairs(model, items, predicted),
            records,
            estimator,
            combination,
        ));
    }
    Ok(checks)
}
