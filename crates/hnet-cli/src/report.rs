//! `hnet report`: the paper's figures for a trained run, as SVG and PNG.
//!
//! - `fig3-samples.png`: test inputs of both views with the predicted masks over them (Fig. 3);
//! - `fig4-force-{x,y,z}`: predicted and true force of 80 test pairs per axis (Fig. 4);
//! - `fig5-error-{x,y,z}`: histograms of the force error per axis (Fig. 5 a-c);
//! - `fig5-loss`, `fig5-miou`, `fig5-force-mae`: training and validation curves (Fig. 5 d-f).

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use burn::tensor::Device;
use hnet_model::metrics::AXES;
use hnet_twin::dataset::{Dataset, Split};
use hnet_units::{ImageSize, TipForce};
use image::{Rgb, RgbImage};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::backend::BackendChoice;
use crate::data::StereoSplit;
use crate::evaluation::{EvalOptions, evaluate};
use crate::network::{load_run, predict};
use crate::run_dir::{EpochRow, LOSS_METRIC, RunDir};
use crate::training::metrics::Quantity;
use hnet_model::predictor::Predictor;

#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Run folder of `hnet train`.
    #[arg(long)]
    run: PathBuf,
    /// Dataset folder (the one the run was trained on by default).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Output folder (the run's `report/` by default).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Where to compute.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
}

const FONT_PATHS: [&str; 4] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/Library/Fonts/Arial.ttf",
];

/// Registers a system TrueType font for the plots' text (plotters draws text with ab_glyph).
fn register_font() -> anyhow::Result<()> {
    let path = std::env::var("HNET_FONT")
        .ok()
        .map(PathBuf::from)
        .or_else(|| FONT_PATHS.iter().map(PathBuf::from).find(|p| p.is_file()))
        .context(
            "no TrueType font for the plots: install fonts-dejavu-core or set HNET_FONT to a .ttf file",
        )?;
    let bytes =
        std::fs::read(&path).with_context(|| format!("cannot read font '{}'", path.display()))?;
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        Box::leak(bytes.into_boxed_slice()),
    )
    .map_err(|_| anyhow::anyhow!("'{}' is not a usable TrueType font", path.display()))
}

/// One test pair's true and predicted tip force, N.
struct ForcePoint {
    truth: TipForce,
    predicted: TipForce,
}

/// One chart of the report.
enum Figure<'a> {
    /// Fig. 4: predicted and true force along one axis.
    Force {
        axis: usize,
        predictions: &'a [ForcePoint],
    },
    /// Fig. 5 a-c: force error histogram along one axis.
    Errors {
        axis: usize,
        predictions: &'a [ForcePoint],
    },
    /// Fig. 5 d-f: a metric over the epochs, training and validation.
    Curve {
        rows: &'a [EpochRow],
        metric: &'a str,
        title: &'a str,
    },
}

impl Figure<'_> {
    fn draw<DB: PlotBackend>(&self, area: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
        area.fill(&WHITE)?;
        match *self {
            Figure::Force { axis, predictions } => force_plot(area, axis, predictions),
            Figure::Errors { axis, predictions } => error_histogram(area, axis, predictions),
            Figure::Curve {
                rows,
                metric,
                title,
            } => curve(area, rows, metric, title),
        }
    }

    /// Writes the chart as `stem.svg` and `stem.png` in `out`.
    fn save(&self, out: &Path, stem: &str, size: (u32, u32)) -> anyhow::Result<()> {
        let svg = out.join(format!("{stem}.svg"));
        {
            let root = SVGBackend::new(&svg, size).into_drawing_area();
            self.draw(&root)?;
            root.present()?;
        }
        let mut buffer = vec![0u8; (size.0 * size.1 * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buffer, size).into_drawing_area();
            self.draw(&root)?;
            root.present()?;
        }
        let png = out.join(format!("{stem}.png"));
        RgbImage::from_raw(size.0, size.1, buffer)
            .context("plot buffer")?
            .save(&png)
            .with_context(|| format!("cannot write '{}'", png.display()))
    }
}

/// A plotters backend whose errors `anyhow` can carry: every figure is drawn on SVG and on a
/// bitmap.
trait PlotBackend: DrawingBackend<ErrorType: 'static> {}

impl<B: DrawingBackend<ErrorType: 'static>> PlotBackend for B {}

fn range_of(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-3);
    (lo - pad, hi + pad)
}

/// A chart of the report: `f64` on both axes.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A chart as every figure of the report has: its caption, the `(x, y)` ranges with the axes'
/// descriptions, and `y_labels` pixels for the y axis' tick labels.
fn chart<'a, DB: PlotBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    (x, y): (Range<f64>, Range<f64>),
    [x_desc, y_desc]: [&str; 2],
    y_labels: u32,
) -> anyhow::Result<Chart<'a, DB>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(y_labels)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}

/// Draws `points` as a line of `colour`, named `label` in the legend.
fn line<'a, DB: PlotBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    points: impl IntoIterator<Item = (f64, f64)>,
    colour: RGBColor,
    label: &str,
) -> anyhow::Result<()> {
    chart
        .draw_series(LineSeries::new(points, colour.stroke_width(2)))?
        .label(label)
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2)));
    Ok(())
}

/// Draws the legend of the chart's lines.
fn legend<'a, DB: PlotBackend + 'a>(chart: &mut Chart<'a, DB>) -> anyhow::Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

fn force_plot<DB: PlotBackend>(
    area: &DrawingArea<DB, Shift>,
    axis: usize,
    predictions: &[ForcePoint],
) -> anyhow::Result<()> {
    let shown = &predictions[..predictions.len().min(80)];
    let (lo, hi) = range_of(
        shown
            .iter()
            .flat_map(|p| [f64::from(p.truth[axis]), f64::from(p.predicted[axis])]),
    );
    let mut chart = chart(
        area,
        &format!("F{} on {} test pairs", AXES[axis], shown.len()),
        (0f64..shown.len() as f64, lo..hi),
        ["test pair", "force (N)"],
        56,
    )?;
    /// A curve of the figure: its label, colour and which force of a pair it draws.
    type Curve = (&'static str, RGBColor, fn(&ForcePoint) -> TipForce);
    let curves: [Curve; 2] = [
        ("true", BLACK, |p| p.truth),
        ("predicted", RED, |p| p.predicted),
    ];
    for (label, colour, force) in curves {
        let points = shown
            .iter()
            .enumerate()
            .map(|(i, p)| (i as f64, f64::from(force(p)[axis])));
        line(&mut chart, points, colour, label)?;
    }
    legend(&mut chart)
}

fn error_histogram<DB: PlotBackend>(
    area: &DrawingArea<DB, Shift>,
    axis: usize,
    predictions: &[ForcePoint],
) -> anyhow::Result<()> {
    let errors: Vec<f64> = predictions
        .iter()
        .map(|p| f64::from(p.predicted[axis] - p.truth[axis]))
        .collect();
    let limit = errors.iter().fold(1e-3f64, |m, e| m.max(e.abs())) * 1.05;
    let bins = 30usize;
    let width = 2.0 * limit / bins as f64;
    let mut counts = vec![0u32; bins];
    for e in &errors {
        let b = (((e + limit) / width) as usize).min(bins - 1);
        counts[b] += 1;
    }
    let top = f64::from(*counts.iter().max().unwrap_or(&1)) * 1.1;
    let mut chart = chart(
        area,
        &format!("F{} error ({} pairs)", AXES[axis], errors.len()),
        (-limit..limit, 0f64..top.max(1.0)),
        ["predicted - measured (N)", "pairs"],
        48,
    )?;
    chart.draw_series(counts.iter().enumerate().map(|(i, &c)| {
        let x0 = -limit + i as f64 * width;
        Rectangle::new(
            [(x0, 0.0), (x0 + width, f64::from(c))],
            BLUE.mix(0.6).filled(),
        )
    }))?;
    Ok(())
}

fn curve<DB: PlotBackend>(
    area: &DrawingArea<DB, Shift>,
    rows: &[EpochRow],
    metric: &str,
    title: &str,
) -> anyhow::Result<()> {
    let series = |split: &str| -> Vec<(f64, f64)> {
        rows.iter()
            .filter(|r| r.split == split)
            .filter_map(|r| r.values.get(metric).map(|v| (r.epoch as f64, *v)))
            .collect()
    };
    let (train, valid) = (series("train"), series("valid"));
    let epochs = rows.iter().map(|r| r.epoch).max().unwrap_or(1) as f64;
    let (lo, hi) = range_of(train.iter().chain(&valid).map(|p| p.1));
    let mut chart = chart(
        area,
        title,
        (0.5f64..epochs + 0.5, lo..hi),
        ["epoch", metric],
        60,
    )?;
    for (points, colour, label) in [(train, BLUE, "training"), (valid, RED, "validation")] {
        line(&mut chart, points.clone(), colour, label)?;
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 3, colour.filled())),
        )?;
    }
    legend(&mut chart)
}

/// Fig. 3: rows of (view A, view B, view A with its predicted mask, view B with its mask).
fn sample_sheet(
    model: &Predictor,
    data: &Path,
    out: &Path,
    device: &Device,
) -> anyhow::Result<Option<PathBuf>> {
    if !model.spec.heads().0 {
        return Ok(None);
    }
    let dataset = Dataset::open(data)?;
    let split = StereoSplit::load(&dataset, Split::Test, model.image_size, Some(4))?;
    let ImageSize {
        width: w,
        height: h,
    } = model.image_size;
    let (tile_w, tile_h, gap) = (w as u32, h as u32, 4u32);
    let rows = split.items.len() as u32;
    let mut sheet = RgbImage::from_pixel(
        4 * tile_w + 5 * gap,
        rows * (tile_h + gap) + gap,
        Rgb([255, 255, 255]),
    );
    let mut r = 0u32;
    predict(model, &split.items, 4, device, |item, masks, _| {
        let Some(masks) = masks else { return };
        let views = [&item.view_a, &item.view_b];
        for (c, tile) in (0..4).map(|c| (c, c % 2)) {
            let overlay = c >= 2;
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    let mut px = [
                        views[tile][i * 3],
                        views[tile][i * 3 + 1],
                        views[tile][i * 3 + 2],
                    ];
                    if overlay {
                        let m = masks[tile][i];
                        // Predicted catheter in orange over the image.
                        px = [
                            (f32::from(px[0]) * (1.0 - 0.6 * m) + 255.0 * 0.6 * m) as u8,
                            (f32::from(px[1]) * (1.0 - 0.6 * m) + 140.0 * 0.6 * m) as u8,
                            (f32::from(px[2]) * (1.0 - 0.6 * m)) as u8,
                        ];
                    }
                    sheet.put_pixel(
                        gap + c as u32 * (tile_w + gap) + x as u32,
                        gap + r * (tile_h + gap) + y as u32,
                        Rgb(px),
                    );
                }
            }
        }
        r += 1;
    })?;
    let path = out.join("fig3-samples.png");
    sheet
        .save(&path)
        .with_context(|| format!("cannot write '{}'", path.display()))?;
    Ok(Some(path))
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    register_font()?;
    let run = RunDir::new(&args.run);
    let data = match &args.data {
        Some(d) => d.clone(),
        None => run.read_info()?.data,
    };
    let out = args.out.clone().unwrap_or_else(|| run.report_dir());
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create '{}'", out.display()))?;
    let rows = run.epoch_metrics()?;
    if rows.is_empty() {
        bail!("'{}' has no training logs", args.run.display());
    }
    let device = args.backend.device()?;
    let model = load_run(&run, &device)?;
    let (_, predictions) = evaluate(
        &model,
        &data,
        Split::Test,
        &device,
        16,
        &EvalOptions::default(),
    )?;
    // Each figure with its file stem and size in pixels.
    let mut figures = Vec::new();
    let forces: Vec<ForcePoint> = predictions
        .iter()
        .filter_map(|p| {
            Some(ForcePoint {
                truth: p.truth,
                predicted: p.predicted?,
            })
        })
        .collect();
    if !forces.is_empty() {
        let predictions = &forces;
        for (axis, name) in AXES.iter().enumerate() {
            let force = Figure::Force { axis, predictions };
            figures.push((force, format!("fig4-force-{name}"), (900, 420)));
            let errors = Figure::Errors { axis, predictions };
            figures.push((errors, format!("fig5-error-{name}"), (520, 420)));
        }
    }
    for (metric, stem, title) in [
        (LOSS_METRIC, "fig5-loss", "Loss (eq. 7)"),
        (Quantity::MIoU.name(), "fig5-miou", "Segmentation mIoU"),
        (Quantity::ForceMae.name(), "fig5-force-mae", "Force MAE (N)"),
    ] {
        if rows.iter().any(|r| r.values.contains_key(metric)) {
            let rows = &rows;
            let curve = Figure::Curve {
                rows,
                metric,
                title,
            };
            figures.push((curve, stem.to_string(), (620, 420)));
        }
    }
    for (figure, stem, size) in &figures {
        figure.save(&out, stem, *size)?;
    }
    let sheet = sample_sheet(&model, &data, &out, &device)?;
    eprintln!(
        "wrote {} figures (SVG and PNG){} to {}",
        figures.len(),
        if sheet.is_some() {
            " and fig3-samples.png"
        } else {
            " (no fig3-samples.png: the network does not segment)"
        },
        out.display()
    );
    Ok(())
}
