//! `hnet study ceiling`: how much of the tip force a dataset's geometry lets any model recover,
//! measured with no network at all, so that every H-Net row in docs/results.md can be read
//! against what the data allows.
//!
//! For each simulated pair it takes the record's exact 3D centreline (resampled to `--points`
//! points by arc length), its exact 2D projections through both views' camera matrices (sub-pixel),
//! and those projections rounded to whole pixels of an image `--sizes` pixels wide (what a mask
//! at that resolution can show without sub-pixel detail). A kernel ridge regressor (RBF kernel)
//! learns the force from each input on the train split; its two settings (kernel width, ridge)
//! are chosen on the val split; R² per axis is reported on the test split, by the same Table I
//! code as `hnet eval`.
//!
//! `hnet study mismatch` ([`crate::mismatch`]) measures the blind force estimate on sets that
//! depart from what the estimators assume.
//!
//! `hnet study features` fits the same regressor to a trained H-Net's pooled features (its force
//! head's input) and puts it beside the head's own estimates on the test split: if the
//! regressor does much better, the head (its training) limits the force; if not, the features do.
//!
//! The regressor is solved with nalgebra's Cholesky factorisation (a maintained linear-algebra
//! crate; the Gram matrix of `n` training pairs is `n x n`, so `--max-train` bounds the time:
//! about O(n³) per setting tried).

use std::path::PathBuf;

use anyhow::{Context, bail};
use hnet_model::architectures::StereoModel;
use hnet_model::metrics::{ForceAccumulator, ForceMetrics};
use hnet_twin::dataset::simulate::{SampleRecord, read_sample_record};
use hnet_twin::dataset::{Dataset, Split};
use hnet_twin::reconstruction::epipolar::project;
use hnet_twin::vec3::Vec3;
use hnet_units::TipForce;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Serialize;

use crate::data::{StereoBatcher, StereoSplit};

/// Studies of what a dataset allows.
#[derive(clap::Args, Debug)]
pub struct StudyArgs {
    #[command(subcommand)]
    study: Study,
}

#[derive(clap::Subcommand, Debug)]
enum Study {
    /// The force a non-deep regressor recovers from each pair's exact geometry: the 3D
    /// centreline, its exact 2D projections, and those rounded to whole pixels at given sizes.
    Ceiling(CeilingArgs),
    /// The force the same regressor recovers from a trained H-Net's pooled features (its force
    /// head's input), beside what the head itself makes of them: whether the features or the
    /// head limit the network's force.
    Features(FeaturesArgs),
    /// The blind force estimate on test data the estimators' model does not share: the
    /// catheter off its catalogue values, the base anywhere, C-arm header errors, radiographs.
    Mismatch(crate::mismatch::MismatchArgs),
    /// How often a network's masks find a catheter where there is none (chest radiographs,
    /// phantom views, noise, blank images), and miss one where there is: the rule that
    /// withholds a force from views without a catheter.
    NoCatheter(crate::no_catheter::NoCatheterArgs),
}

/// `hnet study features`.
#[derive(clap::Args, Debug)]
pub struct FeaturesArgs {
    /// H-Net weights (`model.bpk`).
    #[arg(long)]
    weights: PathBuf,
    /// A dataset with train, val and test splits.
    #[arg(long)]
    data: PathBuf,
    /// Training pairs used at most (the time grows with the cube of this).
    #[arg(long, default_value_t = 1500)]
    max_train: usize,
    /// Validation and test pairs used at most, each.
    #[arg(long, default_value_t = 600)]
    max_eval: usize,
}

/// `hnet study ceiling`.
#[derive(clap::Args, Debug)]
pub struct CeilingArgs {
    /// A dataset made by `hnet simulate` (its records hold the geometry).
    #[arg(long)]
    data: PathBuf,
    /// Image widths (pixels) to round the 2D projections at, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "64,128,224")]
    sizes: Vec<usize>,
    /// Centreline points per pair (resampled by arc length).
    #[arg(long, default_value_t = 16)]
    points: usize,
    /// Training pairs used at most (the time grows with the cube of this).
    #[arg(long, default_value_t = 3000)]
    max_train: usize,
    /// Print the results as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// What the regressor sees of a pair.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "input", rename_all = "snake_case")]
pub enum GeometryInput {
    /// The exact 3D centreline, mm.
    Centreline3d,
    /// Its exact projections in both views, pixels.
    Projections2d,
    /// Those projections rounded to whole pixels of an image `width` pixels wide.
    RoundedProjections {
        /// Image width (and height, as the dataset's images are square), pixels.
        width: usize,
    },
}

impl GeometryInput {
    fn describe(self) -> String {
        match self {
            Self::Centreline3d => "3D centreline (exact)".into(),
            Self::Projections2d => "2D projections, both views (exact)".into(),
            Self::RoundedProjections { width } => {
                format!("2D projections rounded to whole pixels at {width} px")
            }
        }
    }

    /// The features of one pair.
    fn features(self, record: &SampleRecord, points: usize) -> Vec<f64> {
        let centreline = resample_by_arc(&record.centreline_mm, points);
        match self {
            Self::Centreline3d => centreline.iter().flat_map(|p| p.0).collect(),
            Self::Projections2d | Self::RoundedProjections { .. } => {
                let mut features = Vec::with_capacity(4 * points);
                for view in &record.views {
                    let scale = match self {
                        Self::RoundedProjections { width } => {
                            width as f64 / view.carm.image_size.width as f64
                        }
                        _ => 1.0,
                    };
                    for p in &centreline {
                        // A centreline point is in front of both views: it was imaged.
                        let [u, v] = project(&view.camera_matrix, *p).unwrap_or([f64::NAN; 2]);
                        let [u, v] = [u * scale, v * scale];
                        match self {
                            Self::RoundedProjections { .. } => {
                                features.extend([u.floor() + 0.5, v.floor() + 0.5])
                            }
                            _ => features.extend([u, v]),
                        }
                    }
                }
                features
            }
        }
    }
}

/// `n` points evenly spaced by arc length along a polyline (its ends included).
fn resample_by_arc(polyline: &[Vec3], n: usize) -> Vec<Vec3> {
    let mut arc = vec![0.0];
    for w in polyline.windows(2) {
        arc.push(arc.last().unwrap() + (w[1] - w[0]).norm());
    }
    let total = *arc.last().unwrap();
    let mut segment = 0;
    (0..n)
        .map(|i| {
            let s = total * i as f64 / (n - 1).max(1) as f64;
            while segment + 2 < arc.len() && arc[segment + 1] < s {
                segment += 1;
            }
            let (a, b) = (arc[segment], arc[segment + 1]);
            let t = if b > a { (s - a) / (b - a) } else { 0.0 };
            polyline[segment] + (polyline[segment + 1] - polyline[segment]) * t
        })
        .collect()
}

/// One split's features (rows) and forces (N).
struct Samples {
    features: DMatrix<f64>,
    forces: Vec<[f64; 3]>,
}

impl Samples {
    fn new(records: &[(SampleRecord, TipForce)], input: GeometryInput, points: usize) -> Self {
        let rows: Vec<Vec<f64>> = records
            .par_iter()
            .map(|(r, _)| input.features(r, points))
            .collect();
        let columns = rows.first().map_or(0, Vec::len);
        Self {
            features: DMatrix::from_fn(rows.len(), columns, |i, j| rows[i][j]),
            forces: records.iter().map(|(_, f)| f.to_f64()).collect(),
        }
    }
}

/// Kernel ridge regression with an RBF kernel on standardised features and targets.
struct KernelRidge {
    /// Standardised training features (rows).
    train: DMatrix<f64>,
    /// Per-feature mean and standard deviation of the training set.
    feature_scale: Vec<(f64, f64)>,
    /// Per-axis mean and standard deviation of the training forces (N).
    force_scale: [(f64, f64); 3],
    /// The kernel's `γ` in `exp(-γ |x - x'|²)`.
    gamma: f64,
    /// Dual coefficients `[n, 3]`.
    dual: DMatrix<f64>,
}

fn mean_and_std(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count().max(1) as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt().max(1e-12))
}

fn standardise(features: &DMatrix<f64>, scale: &[(f64, f64)]) -> DMatrix<f64> {
    DMatrix::from_fn(features.nrows(), features.ncols(), |i, j| {
        (features[(i, j)] - scale[j].0) / scale[j].1
    })
}

/// `exp(-γ |a_i - b_j|²)` for every row `i` of `a` and `j` of `b`.
fn rbf_kernel(a: &DMatrix<f64>, b: &DMatrix<f64>, gamma: f64) -> DMatrix<f64> {
    let squared =
        |m: &DMatrix<f64>| -> Vec<f64> { m.row_iter().map(|r| r.norm_squared()).collect() };
    let (na, nb) = (squared(a), squared(b));
    let dot = a * b.transpose();
    DMatrix::from_fn(a.nrows(), b.nrows(), |i, j| {
        (-gamma * (na[i] + nb[j] - 2.0 * dot[(i, j)]).max(0.0)).exp()
    })
}

/// The median squared distance between standardised training rows (of a subsample): the
/// kernel width's natural unit.
fn median_squared_distance(train: &DMatrix<f64>) -> f64 {
    let step = (train.nrows() / 300).max(1);
    let rows: Vec<_> = train.row_iter().step_by(step).collect();
    let mut d: Vec<f64> = Vec::new();
    for (i, a) in rows.iter().enumerate() {
        for b in &rows[i + 1..] {
            d.push((a - b).norm_squared());
        }
    }
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(1.0).max(1e-12)
}

impl KernelRidge {
    /// Fits `gram` (the kernel of the standardised `train` rows, `γ` = `gamma`) with ridge
    /// `lambda`; `None` when the regularised matrix is not positive definite.
    fn fit(
        samples: &Samples,
        train: DMatrix<f64>,
        feature_scale: Vec<(f64, f64)>,
        gram: &DMatrix<f64>,
        gamma: f64,
        lambda: f64,
    ) -> Option<Self> {
        let n = samples.forces.len();
        let force_scale =
            [0, 1, 2].map(|axis| mean_and_std(samples.forces.iter().map(move |f| f[axis])));
        let targets = DMatrix::from_fn(n, 3, |i, axis| {
            (samples.forces[i][axis] - force_scale[axis].0) / force_scale[axis].1
        });
        let regularised = gram + DMatrix::identity(n, n) * lambda;
        let dual = regularised.cholesky()?.solve(&targets);
        Some(Self {
            train,
            feature_scale,
            force_scale,
            gamma,
            dual,
        })
    }

    /// Forces (N) predicted for `features` (rows).
    fn predict(&self, features: &DMatrix<f64>) -> Vec<[f64; 3]> {
        let x = standardise(features, &self.feature_scale);
        let standardised = rbf_kernel(&x, &self.train, self.gamma) * &self.dual;
        (0..x.nrows())
            .map(|i| {
                [0, 1, 2].map(|axis| {
                    standardised[(i, axis)] * self.force_scale[axis].1 + self.force_scale[axis].0
                })
            })
            .collect()
    }
}

/// Table I of `predicted` against the `truth`.
fn force_metrics(predicted: &[[f64; 3]], truth: &[[f64; 3]]) -> ForceMetrics {
    let mut acc = ForceAccumulator::new();
    for (p, t) in predicted.iter().zip(truth) {
        acc.push(TipForce::from_f64(*p), TipForce::from_f64(*t));
    }
    acc.finish().expect("the splits are not empty")
}

/// The mean R² over the axes (undefined axes count as 0).
fn mean_r2(m: &ForceMetrics) -> f64 {
    m.axes.iter().map(|a| a.r2.unwrap_or(0.0)).sum::<f64>() / 3.0
}

/// The result for one input.
#[derive(Debug, Clone, Serialize)]
pub struct CeilingRow {
    /// What the regressor saw.
    #[serde(flatten)]
    pub input: GeometryInput,
    /// Training pairs.
    pub train_pairs: usize,
    /// Kernel width chosen on the val split, as a multiple of 1 / (median squared distance).
    pub gamma_factor: f64,
    /// Ridge chosen on the val split.
    pub ridge: f64,
    /// Table I on the test split.
    pub test: ForceMetrics,
}

/// Fits and evaluates one input, choosing the kernel width and ridge on the val split.
fn study_input(
    input: GeometryInput,
    points: usize,
    [train, val, test]: [&[(SampleRecord, TipForce)]; 3],
) -> anyhow::Result<CeilingRow> {
    let [train, val, test] = [train, val, test].map(|split| Samples::new(split, input, points));
    let fit = fit_and_test(&train, &val, &test).with_context(|| input.describe())?;
    Ok(CeilingRow {
        input,
        train_pairs: train.forces.len(),
        gamma_factor: fit.gamma_factor,
        ridge: fit.ridge,
        test: fit.test,
    })
}

/// A kernel ridge fit chosen on the val split and its Table I on the test split.
struct Fit {
    gamma_factor: f64,
    ridge: f64,
    test: ForceMetrics,
}

/// Fits the regressor on `train` with each kernel width and ridge, keeps the best on `val`,
/// and measures it on `test`.
fn fit_and_test(train: &Samples, val: &Samples, test: &Samples) -> anyhow::Result<Fit> {
    let feature_scale: Vec<(f64, f64)> = (0..train.features.ncols())
        .map(|j| mean_and_std(train.features.column(j).iter().copied()))
        .collect();
    let x = standardise(&train.features, &feature_scale);
    let unit = 1.0 / median_squared_distance(&x);
    let mut best: Option<(f64, f64, f64, KernelRidge)> = None;
    for gamma_factor in [0.25, 1.0, 4.0] {
        let gamma = gamma_factor * unit;
        let gram = rbf_kernel(&x, &x, gamma);
        for ridge in [1e-4, 1e-3, 1e-2] {
            let Some(model) =
                KernelRidge::fit(train, x.clone(), feature_scale.clone(), &gram, gamma, ridge)
            else {
                continue;
            };
            let score = mean_r2(&force_metrics(&model.predict(&val.features), &val.forces));
            if best.as_ref().is_none_or(|b| score > b.0) {
                best = Some((score, gamma_factor, ridge, model));
            }
        }
    }
    let Some((_, gamma_factor, ridge, model)) = best else {
        bail!("no kernel setting gave a solvable system");
    };
    Ok(Fit {
        gamma_factor,
        ridge,
        test: force_metrics(&model.predict(&test.features), &test.forces),
    })
}

fn load_split(
    dataset: &Dataset,
    split: Split,
    limit: usize,
) -> anyhow::Result<Vec<(SampleRecord, TipForce)>> {
    let rows: Vec<_> = dataset.split(split).take(limit).collect();
    if rows.is_empty() {
        bail!(
            "{} has no pairs in its {} split",
            dataset.root.display(),
            split.name()
        );
    }
    rows.par_iter()
        .map(|row| Ok((read_sample_record(dataset, &row.id)?, row.force_n)))
        .collect()
}

/// Runs `hnet study`.
pub fn run(args: &StudyArgs) -> anyhow::Result<()> {
    let args = match &args.study {
        Study::Ceiling(args) => args,
        Study::Features(args) => return study_features(args),
        Study::Mismatch(args) => return crate::mismatch::run(args),
        Study::NoCatheter(args) => return crate::no_catheter::run(args),
    };
    if args.points < 2 {
        bail!("--points must be at least 2");
    }
    if args.sizes.contains(&0) {
        bail!("--sizes must be positive pixel counts");
    }
    let dataset = Dataset::open(&args.data)?;
    let context = || format!("reading the records of {}", args.data.display());
    let train = load_split(&dataset, Split::Train, args.max_train).with_context(context)?;
    let val = load_split(&dataset, Split::Val, usize::MAX).with_context(context)?;
    let test = load_split(&dataset, Split::Test, usize::MAX).with_context(context)?;
    let inputs = [GeometryInput::Centreline3d, GeometryInput::Projections2d]
        .into_iter()
        .chain(
            args.sizes
                .iter()
                .map(|&width| GeometryInput::RoundedProjections { width }),
        );
    let mut rows = Vec::new();
    for input in inputs {
        eprintln!("fitting on {} ...", input.describe());
        rows.push(study_input(input, args.points, [&train, &val, &test])?);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "Force ceiling of {} ({} train, {} val, {} test pairs; kernel ridge, RBF; {} points per centreline)\n",
        args.data.display(),
        train.len(),
        val.len(),
        test.len(),
        args.points
    );
    println!("| input | R² Fx | R² Fy | R² Fz | R² mean | RMSE (N) |");
    println!("| --- | --- | --- | --- | --- | --- |");
    for row in &rows {
        let r2 = |i: usize| {
            row.test.axes[i]
                .r2
                .map_or("n/a".into(), |v| format!("{v:.3}"))
        };
        println!(
            "| {} | {} | {} | {} | {:.3} | {:.4} |",
            row.input.describe(),
            r2(0),
            r2(1),
            r2(2),
            mean_r2(&row.test),
            row.test.overall.rmse
        );
    }
    Ok(())
}

/// The pooled features (rows) and the network's own force estimates (N) of `split`'s pairs.
fn pooled_features(
    net: &hnet_model::HNet,
    dataset: &Dataset,
    split: Split,
    size: hnet_units::ImageSize,
    limit: usize,
) -> anyhow::Result<(Samples, Vec<[f64; 3]>)> {
    use burn::data::dataloader::batcher::Batcher;
    use hnet_model::inference::host_values;

    let pairs = StereoSplit::load(dataset, split, size, Some(limit))?;
    if pairs.items.is_empty() {
        bail!(
            "{} has no pairs in its {} split",
            dataset.root.display(),
            split.name()
        );
    }
    let device = burn::tensor::Device::flex();
    let batcher = StereoBatcher { size };
    let (mut rows, mut forces, mut estimates) = (Vec::new(), Vec::new(), Vec::new());
    for chunk in pairs.items.chunks(16) {
        let batch = batcher.batch(chunk.to_vec(), &device);
        let (output, features) = net.forward_with_features(batch.view_a, batch.view_b);
        let width = features.dims()[1];
        let values = host_values(features)?;
        rows.extend(
            values
                .chunks_exact(width)
                .map(|r| r.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()),
        );
        let estimated = host_values(output.force)?;
        estimates.extend(
            estimated
                .chunks_exact(3)
                .map(|f| [0, 1, 2].map(|i| f64::from(f[i]))),
        );
        forces.extend(chunk.iter().map(|item| item.force_n.to_f64()));
    }
    let columns = rows.first().map_or(0, Vec::len);
    let samples = Samples {
        features: DMatrix::from_fn(rows.len(), columns, |i, j| rows[i][j]),
        forces,
    };
    Ok((samples, estimates))
}

/// `hnet study features`: the force in a trained H-Net's pooled features.
fn study_features(args: &FeaturesArgs) -> anyhow::Result<()> {
    let device = burn::tensor::Device::flex();
    let model = crate::network::load_weights(&args.weights, None, &device)?;
    let StereoModel::Hnet(net) = &model.net else {
        bail!(
            "weights file '{}' holds a `{}` network: only H-Net has pooled features",
            args.weights.display(),
            model.spec.name()
        );
    };
    let dataset = Dataset::open(&args.data)?;
    let features = |split, limit| {
        pooled_features(net, &dataset, split, model.image_size, limit)
            .with_context(|| format!("the {} split of {}", split.name(), args.data.display()))
    };
    let (train, _) = features(Split::Train, args.max_train)?;
    let (val, _) = features(Split::Val, args.max_eval)?;
    let (test, head) = features(Split::Test, args.max_eval)?;
    let fit = fit_and_test(&train, &val, &test)?;
    let own = force_metrics(&head, &test.forces);
    println!(
        "Force in the pooled features of {} on {} ({} train, {} val, {} test pairs; {} features; kernel ridge, RBF)\n",
        args.weights.display(),
        args.data.display(),
        train.forces.len(),
        val.forces.len(),
        test.forces.len(),
        train.features.ncols()
    );
    println!("| from | R² Fx | R² Fy | R² Fz | R² mean | RMSE (N) |");
    println!("| --- | --- | --- | --- | --- | --- |");
    for (name, metrics) in [
        ("the network's force head", &own),
        ("kernel ridge on its pooled features", &fit.test),
    ] {
        let r2 = |i: usize| {
            metrics.axes[i]
                .r2
                .map_or("n/a".into(), |v| format!("{v:.3}"))
        };
        println!(
            "| {name} | {} | {} | {} | {:.3} | {:.4} |",
            r2(0),
            r2(1),
            r2(2),
            mean_r2(metrics),
            metrics.overall.rmse
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_smooth_function_is_learned_and_resampling_keeps_the_ends() {
        // Forces that are a smooth function of 2 features: kernel ridge must recover them.
        let sample = |i: usize| {
            let (a, b) = ((i as f64 * 0.37).sin(), (i as f64 * 0.11).cos());
            (vec![a, b], [a + b, a * b, (2.0 * a).sin()])
        };
        let make = |range: std::ops::Range<usize>| {
            let all: Vec<_> = range.map(sample).collect();
            Samples {
                features: DMatrix::from_fn(all.len(), 2, |i, j| all[i].0[j]),
                forces: all.iter().map(|s| s.1).collect(),
            }
        };
        let (train, test) = (make(0..300), make(1000..1100));
        let scale: Vec<_> = (0..2)
            .map(|j| mean_and_std(train.features.column(j).iter().copied()))
            .collect();
        let x = standardise(&train.features, &scale);
        let gamma = 1.0 / median_squared_distance(&x);
        let gram = rbf_kernel(&x, &x, gamma);
        let model = KernelRidge::fit(&train, x, scale, &gram, gamma, 1e-4).unwrap();
        let metrics = force_metrics(&model.predict(&test.features), &test.forces);
        assert!(mean_r2(&metrics) > 0.99, "{metrics:?}");

        let line = [
            Vec3([0.0, 0.0, 0.0]),
            Vec3([1.0, 0.0, 0.0]),
            Vec3([3.0, 0.0, 0.0]),
        ];
        let points = resample_by_arc(&line, 4);
        assert_eq!(points.len(), 4);
        assert_eq!(points[0], line[0]);
        assert!((points[3] - line[2]).norm() < 1e-12);
        assert!((points[1][0] - 1.0).abs() < 1e-12);
    }
}
