//! Importing real recordings: two folders of images (one per view, matching file names) and a CSV
//! of tip forces become a dataset in the same format as simulated data, with masks made by
//! thresholding as the paper did.
//!
//! The forces CSV has a header with a column naming the image file (`image`, `file`, `frame` or
//! `name`; with or without extension) and the columns `fx`, `fy`, `fz` in newtons.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use hnet_units::ImageSize;
use serde_json::json;

use crate::dataset::force_table::{ForceRow, ForceTableError, read_force_table};
use crate::dataset::label_origin::LabelOrigin;
use crate::dataset::{
    DatasetError, DatasetHeader, DatasetWriter, ImageRef, ManifestRow, assign_splits,
    image_size_of, is_valid_id, resized, sample_files,
};
use crate::simulator::scene::{luma, otsu_threshold, threshold_mask};

/// How masks are made from the recorded images.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskThreshold {
    /// Pixels at or below this grey level (0-255) are catheter.
    Level(u8),
    /// Otsu's level, per image.
    Otsu,
}

impl MaskThreshold {
    /// How a dataset header records it: the grey level, or `"otsu"`.
    pub fn record(self) -> serde_json::Value {
        match self {
            MaskThreshold::Level(level) => serde_json::json!(level),
            MaskThreshold::Otsu => serde_json::json!("otsu"),
        }
    }
}

/// What to import and how.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// Folder of view A images.
    pub view_a: PathBuf,
    /// Folder of view B images.
    pub view_b: PathBuf,
    /// The forces CSV.
    pub forces: PathBuf,
    /// Output dataset folder.
    pub out: PathBuf,
    /// Mask rule.
    pub threshold: MaskThreshold,
    /// Whether the catheter is brighter than the background (the masks take the pixels above
    /// the level instead).
    pub bright_catheter: bool,
    /// Resize every image to this square size; otherwise all must share the first one's size.
    pub size: Option<usize>,
    /// Report bad rows and go on instead of stopping at the first.
    pub skip_bad: bool,
    /// Seed of the 80/10/10 split.
    pub seed: u64,
    /// Where the forces came from, for rows whose table does not say (its `label_origin`
    /// column, [`crate::dataset::label_origin`]).
    pub label_origin: LabelOrigin,
}

/// A force row's origin: the table's own, else `default`.
pub fn row_origin(row: &ForceRow, default: &LabelOrigin) -> LabelOrigin {
    match row.origin {
        LabelOrigin::Unrecorded => default.clone(),
        ref origin => origin.clone(),
    }
}

/// What an import did.
#[derive(Debug, Default)]
pub struct ImportReport {
    /// Pairs written.
    pub imported: usize,
    /// Why each skipped row was skipped (with `skip_bad`).
    pub skipped: Vec<DatasetError>,
}

/// Extensions of the image files read from folders (recordings here, backgrounds in `hnet
/// simulate`), lower case.
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff"];

/// Whether `path` names an image file by its extension (any case).
pub fn is_image_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// The forces CSV's rows (the key is the image's name), each good or its error.
fn read_forces(path: &Path) -> Result<Vec<Result<ForceRow, DatasetError>>, DatasetError> {
    let bytes =
        std::fs::read(path).map_err(|e| DatasetError::caused_by(path, "cannot be read", e))?;
    let rows = read_force_table(&bytes, &["image", "file", "frame", "name"])
        .map_err(|e| table_error(path, e))?;
    Ok(rows
        .into_iter()
        .map(|row| row.map_err(|e| table_error(path, e)))
        .collect())
}

/// A force table's problem (with its line) as the problem of the file at `path`.
fn table_error(path: &Path, error: ForceTableError) -> DatasetError {
    let problem = error.to_string();
    match error.cause {
        Some(cause) => DatasetError::caused_by(path, problem, cause),
        None => DatasetError::new(path, problem),
    }
}

/// The file of `name` in `folder`: the name itself, or the name with an image extension.
fn find_image(folder: &Path, name: &str) -> Option<PathBuf> {
    let direct = folder.join(name);
    if direct.is_file() {
        return Some(direct);
    }
    IMAGE_EXTENSIONS
        .iter()
        .map(|ext| folder.join(format!("{name}.{ext}")))
        .find(|p| p.is_file())
}

/// An id for the file name: its stem with characters outside the id alphabet replaced.
fn id_for(name: &str) -> String {
    let stem = Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let id: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if is_valid_id(&id) {
        id
    } else {
        format!("x{id}")
    }
}

struct Decoded {
    image: image::DynamicImage,
    path: PathBuf,
}

fn decode(path: &Path) -> Result<Decoded, DatasetError> {
    let bytes =
        std::fs::read(path).map_err(|e| DatasetError::caused_by(path, "cannot be read", e))?;
    let image = image::load_from_memory(&bytes)
        .map_err(|e| DatasetError::caused_by(path, "unreadable image", e))?;
    Ok(Decoded {
        image,
        path: path.to_path_buf(),
    })
}

/// Grey or RGB pixels of an image at the dataset's size, and its channel count.
fn pixels(image: &image::DynamicImage, size: ImageSize) -> (usize, Vec<u8>) {
    let image = resized(image.clone(), size);
    if image.color().has_color() {
        (3, image.to_rgb8().into_raw())
    } else {
        (1, image.to_luma8().into_raw())
    }
}

fn mask_of(channels: usize, pixels: &[u8], options: &ImportOptions) -> Vec<u8> {
    let grey = if channels == 3 {
        luma(pixels)
    } else {
        pixels.to_vec()
    };
    recording_mask(grey, options.threshold, options.bright_catheter)
}

/// The catheter mask of a recorded 8-bit grey image by `threshold` (the one mask rule of every
/// import: image folders here, DICOM cines in `hnet import --dicom-a/--dicom-b`).
pub fn recording_mask(
    mut grey: Vec<u8>,
    threshold: MaskThreshold,
    bright_catheter: bool,
) -> Vec<u8> {
    if bright_catheter {
        grey.iter_mut().for_each(|v| *v = 255 - *v);
    }
    let level = match threshold {
        MaskThreshold::Level(level) if bright_catheter => 255 - level,
        MaskThreshold::Level(level) => level,
        MaskThreshold::Otsu => otsu_threshold(&grey),
    };
    threshold_mask(&grey, level)
}

/// Imports recordings into a dataset. Errors name the file or CSV line; with `skip_bad` bad rows
/// are reported in the result instead and the import goes on.
pub fn import_recordings(
    options: &ImportOptions,
    progress: &dyn Fn(usize, usize),
) -> Result<ImportReport, DatasetError> {
    for folder in [&options.view_a, &options.view_b] {
        if !folder.is_dir() {
            return Err(DatasetError::new(folder, "is not a folder of images"));
        }
    }
    let rows = read_forces(&options.forces)?;
    let mut report = ImportReport::default();
    let mut good = Vec::new();
    let mut ids = HashSet::new();
    let mut size = options.size.map(ImageSize::square);
    let mut size_source: Option<PathBuf> = None;
    let total = rows.len();
    for row in rows {
        let checked = row.and_then(|row| {
            let id = id_for(&row.key);
            if !ids.insert(id.clone()) {
                return Err(DatasetError::new(
                    &options.forces,
                    format!("line {}: `{}` appears twice (id `{id}`)", row.line, row.key),
                ));
            }
            let [a, b] = [&options.view_a, &options.view_b].map(|folder| {
                find_image(folder, &row.key).ok_or_else(|| {
                    DatasetError::new(
                        folder.join(&row.key),
                        format!(
                            "missing (named on line {} of {})",
                            row.line,
                            options.forces.display()
                        ),
                    )
                })
            });
            let (a, b) = (decode(&a?)?, decode(&b?)?);
            let dims = |d: &Decoded| image_size_of(&d.image);
            if dims(&a) != dims(&b) {
                return Err(DatasetError::new(
                    &b.path,
                    format!("is {} but {} is {}", dims(&b), a.path.display(), dims(&a)),
                ));
            }
            match (size, &size_source) {
                (Some(s), Some(first)) if options.size.is_none() && s != dims(&a) => {
                    return Err(DatasetError::new(
                        &a.path,
                        format!(
                            "is {} but {} is {s} (pass --size to resize all images)",
                            dims(&a),
                            first.display(),
                        ),
                    ));
                }
                (None, _) => {
                    size = Some(dims(&a));
                    size_source = Some(a.path.clone());
                }
                _ => {}
            }
            Ok((row, id, a, b))
        });
        match checked {
            Ok(item) => good.push(item),
            Err(e) if options.skip_bad => report.skipped.push(e),
            Err(e) => return Err(e),
        }
    }
    if good.is_empty() {
        return Err(DatasetError::new(
            &options.forces,
            "no usable rows: nothing to import",
        ));
    }
    let size = size.expect("set by the first good row");
    let header = DatasetHeader::new(
        size,
        good.len(),
        json!({
            "generator": "hnet import",
            "view_a": options.view_a,
            "view_b": options.view_b,
            "forces": options.forces,
            "threshold": options.threshold.record(),
            "bright_catheter": options.bright_catheter,
            "seed": options.seed,
        }),
    );
    let writer = DatasetWriter::create_or_resume(&options.out, &header)?;
    let splits = assign_splits(good.len(), options.seed);
    for (n, ((row, id, a, b), split)) in good.into_iter().zip(splits).enumerate() {
        if !writer.has_sample(&id) {
            let (ca, pa) = pixels(&a.image, size);
            let (cb, pb) = pixels(&b.image, size);
            let (ma, mb) = (mask_of(ca, &pa, options), mask_of(cb, &pb, options));
            let ImageSize { width, height } = size;
            let manifest = ManifestRow {
                id: id.clone(),
                split,
                force_n: row.force_n,
                extra: [
                    ("source_a".into(), a.path.display().to_string()),
                    ("source_b".into(), b.path.display().to_string()),
                ]
                .into_iter()
                .chain(row_origin(&row, &options.label_origin).columns())
                .collect(),
            };
            let record = json!({ "csv_line": row.line, "image": row.key });
            let files = sample_files(
                &manifest,
                [(ca, &pa), (cb, &pb), (1, &ma), (1, &mb)].map(|(channels, pixels)| ImageRef {
                    width,
                    height,
                    channels,
                    pixels,
                }),
                &record,
            );
            writer.write_sample(&id, &files)?;
        }
        report.imported += 1;
        progress(n + 1, total);
    }
    writer.finish()?;
    Ok(report)
}
