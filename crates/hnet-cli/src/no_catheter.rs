//! `hnet study no-catheter`: how often a network's masks "find" a catheter where there is none,
//! and miss one where there is, for the rule that withholds a force from views without a
//! catheter ([`hnet_model::inference::catheter_found`]).
//!
//! Views with a catheter: a dataset's pairs. Views without: the twin's X-ray of the phantom (and
//! of `--background` radiographs) rendered with no catheter, the radiographs themselves resized
//! to the network's size, uniform noise, and blank black and white images. For each group, the
//! share of each view's pixels the network calls catheter, the share of views with at least a
//! given share at several thresholds, and the share the rule in use calls "catheter found"
//! (enough pixels and not too many, in one blob long enough for a catheter, smaller blobs beside
//! it set aside).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;
use hnet_twin::dataset::{Dataset, Split, resized};
use hnet_twin::reconstruction::centreline::{
    CatheterSeen, CentrelineSettings, MAX_CATHETER_SHARE, MIN_CATHETER_SHARE, Mask, catheter_seen,
};
use hnet_twin::simulator::scene::{Modality, TwinConfig, render_empty_xray_view, sample_rng};
use hnet_twin::simulator::synthetic_xray::BackgroundSource;
use rand::RngExt;

use crate::backend::BackendChoice;
use crate::data::{StereoItem, StereoSplit};
use crate::network::{load_weights, predict};
use crate::simulate::background_files;

/// `hnet study no-catheter`.
#[derive(clap::Args, Debug)]
pub struct NoCatheterArgs {
    /// Weights to study.
    #[arg(long)]
    weights: PathBuf,
    /// A dataset whose pairs show a catheter (its train split is read).
    #[arg(long)]
    data: PathBuf,
    /// Chest radiographs (files or folders) for the catheter-free radiograph groups.
    #[arg(long = "background")]
    backgrounds: Vec<PathBuf>,
    /// Pairs per group at most.
    #[arg(long, default_value_t = 100)]
    pairs: usize,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
}

/// Thresholds on the share of a view's pixels called catheter, reported side by side.
const THRESHOLDS: [f64; 5] = [0.0005, 0.001, 0.0025, 0.005, 0.01];

fn grey_to_rgb(grey: &[u8]) -> Arc<[u8]> {
    grey.iter().flat_map(|&g| [g, g, g]).collect()
}

fn pair(id: String, a: Arc<[u8]>, b: Arc<[u8]>, pixels: usize) -> StereoItem {
    let empty: Arc<[u8]> = vec![0u8; pixels].into();
    StereoItem {
        view_a: a,
        view_b: b,
        mask_a: empty.clone(),
        mask_b: empty,
        force_n: hnet_units::TipForce::ZERO,
        force_known: false,
        id: id.into(),
    }
}

pub fn run(args: &NoCatheterArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let model = load_weights(&args.weights, None, &device)?;
    anyhow::ensure!(
        model.spec.heads().0,
        "`{}` gives no masks",
        model.spec.name()
    );
    let size = model.image_size;
    let pixels = size.pixels();
    let mut groups: Vec<(String, bool, Vec<StereoItem>)> = Vec::new();

    let dataset = Dataset::open(&args.data)?;
    let mut with = StereoSplit::load(&dataset, Split::Train, size, None)?.items;
    with.truncate(args.pairs);
    groups.push((
        format!("catheter pairs ({})", args.data.display()),
        true,
        with,
    ));

    let twin = TwinConfig::new(Modality::Xray2, size);
    let phantom = [&twin.views.a, &twin.views.b].map(|view| BackgroundSource::phantom(view, 512));
    let radiographs: Vec<BackgroundSource> = background_files(&args.backgrounds)?
        .iter()
        .map(|path| crate::simulate::load_radiograph(path))
        .collect::<anyhow::Result<_>>()?;
    let empty_views = |name: &str, source_of: &dyn Fn(usize, usize) -> BackgroundSource| {
        (0..args.pairs)
            .map(|i| {
                let mut rng = sample_rng(77, i as u64);
                let [a, b] = [0, 1].map(|v| {
                    let view = [&twin.views.a, &twin.views.b][v];
                    grey_to_rgb(&render_empty_xray_view(
                        &twin,
                        view,
                        &source_of(i, v),
                        &mut rng,
                    ))
                });
                pair(format!("{name}-{i}"), a, b, pixels)
            })
            .collect::<Vec<_>>()
    };
    groups.push((
        "twin X-ray of the phantom, no catheter".into(),
        false,
        empty_views("phantom", &|_, v| phantom[v].clone()),
    ));
    if !radiographs.is_empty() {
        groups.push((
            "twin X-ray of chest radiographs, no catheter".into(),
            false,
            empty_views("chest-twin", &|i, v| {
                radiographs[(2 * i + v) % radiographs.len()].clone()
            }),
        ));
        let raw: Vec<Arc<[u8]>> = background_files(&args.backgrounds)?
            .iter()
            .map(|path| -> anyhow::Result<Arc<[u8]>> {
                let image = image::open(path)
                    .with_context(|| format!("cannot read '{}'", path.display()))?;
                Ok(grey_to_rgb(resized(image, size).to_luma8().as_raw()))
            })
            .collect::<anyhow::Result<_>>()?;
        groups.push((
            "chest radiographs as they are".into(),
            false,
            (0..raw.len())
                .map(|i| {
                    pair(
                        format!("chest-{i}"),
                        raw[i].clone(),
                        raw[(i + 1) % raw.len()].clone(),
                        pixels,
                    )
                })
                .collect(),
        ));
    }
    groups.push((
        "uniform noise".into(),
        false,
        (0..args.pairs.min(20))
            .map(|i| {
                let mut rng = sample_rng(78, i as u64);
                let mut noise =
                    || -> Arc<[u8]> { (0..pixels * 3).map(|_| rng.random::<u8>()).collect() };
                let (a, b) = (noise(), noise());
                pair(format!("noise-{i}"), a, b, pixels)
            })
            .collect(),
    ));
    groups.push((
        "blank black and white".into(),
        false,
        vec![pair(
            "blank".into(),
            vec![0u8; pixels * 3].into(),
            vec![255u8; pixels * 3].into(),
            pixels,
        )],
    ));

    let mut report = String::new();
    let _ = writeln!(
        report,
        "Catheter found (share of the view's pixels at or above the mask threshold ≥ t), `{}`\n",
        args.weights.display()
    );
    let _ = write!(report, "| views | catheter? | views | median share |");
    for t in THRESHOLDS {
        let _ = write!(report, " found at t = {:.2} % |", t * 100.0);
    }
    let _ = writeln!(report, " found by the rule | of them, not a clean tube |");
    let _ = writeln!(report, "|{}", " --- |".repeat(6 + THRESHOLDS.len()));
    for (name, has_catheter, items) in &groups {
        let mut shares = Vec::new();
        let mut by_rule = 0;
        let mut tangled = 0;
        predict(&model, items, 16, &device, |_, masks, _| {
            if let Some(masks) = masks {
                for (mask, view) in masks.iter().zip(["A", "B"]) {
                    let mask = Mask::soft(size.width, size.height, mask);
                    shares.push(mask.share_at_half());
                    let settings = CentrelineSettings::default();
                    match catheter_seen(&mask, view, &settings) {
                        Ok(CatheterSeen::Tube) => by_rule += 1,
                        Ok(CatheterSeen::Tangled(_)) => {
                            by_rule += 1;
                            tangled += 1;
                        }
                        Err(_) => {}
                    }
                }
            }
        })?;
        shares.sort_by(f64::total_cmp);
        let median = shares.get(shares.len() / 2).copied().unwrap_or(0.0);
        let _ = write!(
            report,
            "| {name} | {} | {} | {:.3} % |",
            if *has_catheter { "yes" } else { "no" },
            shares.len(),
            median * 100.0
        );
        for t in THRESHOLDS {
            let found = shares.iter().filter(|&&s| s >= t).count();
            let _ = write!(
                report,
                " {:.1} % |",
                100.0 * found as f64 / shares.len().max(1) as f64
            );
        }
        let _ = writeln!(
            report,
            " {:.1} % | {:.1} % |",
            100.0 * by_rule as f64 / shares.len().max(1) as f64,
            100.0 * tangled as f64 / shares.len().max(1) as f64
        );
    }
    let _ = writeln!(
        report,
        "\nThe rule (`hnet_twin::reconstruction::centreline::catheter_seen`): {:.2} % to {:.0} % of the view's \
         pixels read as catheter, in one blob long enough for a catheter (smaller blobs beside it set aside).",
        MIN_CATHETER_SHARE * 100.0,
        MAX_CATHETER_SHARE * 100.0
    );
    print!("{report}");
    Ok(())
}
