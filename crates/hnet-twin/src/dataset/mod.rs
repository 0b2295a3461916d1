//! The on-disk dataset format (version 1), shared by `hnet simulate`, `hnet import`, the browser
//! app's export and the training loader; with what reads and writes it: [`force_table`] (force
//! tables in CSV, for imports and the page's labels), [`label_origin`] (where each force label
//! came from), [`archive`] (the page's export as one file), and natively [`simulate`] (the twin's
//! pairs written as a dataset, and their records), [`shard`] (a simulation in parts and their
//! merge), [`import`] (image folders) and [`files`] (atomic writes).
//!
//! ```text
//! DIR/dataset.json            header: format, version, image size, where the data came from
//! DIR/manifest.csv            one row per stereo pair: id,split,fx,fy,fz[,parameters...]
//!                             (label_origin and its estimate's weights: crate::dataset::label_origin)
//! DIR/samples/<id>_view_a.png view A image (8-bit grey or RGB)
//! DIR/samples/<id>_view_b.png view B image
//! DIR/samples/<id>_mask_a.png view A catheter mask (8-bit, 255 = catheter; soft edges allowed)
//! DIR/samples/<id>_mask_b.png view B catheter mask
//! DIR/samples/<id>.json       the pair's record: its manifest row and, for simulated pairs,
//!                             the 3D centreline (mm) and both camera matrices
//! ```
//!
//! Forces are the tip force in newtons. `split` is `train`, `val` or `test`. Ids are made of
//! ASCII letters, digits, `-`, `_` and `.` so that they are safe file names.
//!
//! Writing is crash-safe without slowing generation down: a pair's record is written after its
//! four images, and a pair counts as complete only when its record parses and each image ends
//! with PNG's closing chunk, so a pair cut short by a kill (or a power loss) is simply made
//! again. The manifest, which readers require, is written last, through a temporary file and a
//! rename. A generation that was killed resumes by skipping the pairs already complete.

use std::fmt;
use std::path::{Path, PathBuf};

use hnet_units::turn::{TurnError, turn_clockwise};
use hnet_units::{ImageSize, TipForce};
use serde::{Deserialize, Serialize};

use crate::dataset::label_origin::{LabelOrigin, UnknownOrigin};

/// `format` field of `dataset.json`.
pub const FORMAT: &str = "hnet-dataset";
/// Version of the layout described above.
pub const VERSION: u32 = 1;
/// Name of the header file.
pub const HEADER_FILE: &str = "dataset.json";
/// Name of the manifest.
pub const MANIFEST_FILE: &str = "manifest.csv";
/// Folder of the samples.
pub const SAMPLES_DIR: &str = "samples";
/// The four images of a pair, in the order view A, view B, mask A, mask B.
pub const SAMPLE_IMAGES: [&str; 4] = ["view_a", "view_b", "mask_a", "mask_b"];

/// Path of one of pair `id`'s images (`kind` from [`SAMPLE_IMAGES`]) relative to the dataset.
pub fn image_path(id: &str, kind: &str) -> String {
    format!("{SAMPLES_DIR}/{id}_{kind}.png")
}

/// Path of pair `id`'s record relative to the dataset.
pub fn record_path(id: &str) -> String {
    format!("{SAMPLES_DIR}/{id}.json")
}

/// The last 12 bytes of every PNG file: the empty `IEND` chunk and its CRC.
#[cfg(not(target_arch = "wasm32"))]
const PNG_END: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];

/// Which part of the data a pair belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Training.
    Train,
    /// Validation (early stopping, model selection).
    Val,
    /// Test (the reported numbers).
    Test,
}

impl Split {
    /// `train`, `val` or `test`.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }

    /// Parses a split name.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "train" => Some(Split::Train),
            "val" => Some(Split::Val),
            "test" => Some(Split::Test),
            _ => None,
        }
    }
}

/// The seeded 80/10/10 split of `n` pairs: a seeded shuffle of the indices, the first 80 % train,
/// the next 10 % validation, the rest test.
pub fn assign_splits(n: usize, seed: u64) -> Vec<Split> {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_5B11_7000_0001);
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    let mut n_val = (n as f64 * 0.1).round() as usize;
    let mut n_test = n - ((n as f64 * 0.8).round() as usize) - n_val;
    // Small sets (such as a few pairs labeled in the app) still get one validation and one test
    // pair, so that training can stop early and evaluation has something to measure.
    if n >= 3 {
        n_val = n_val.max(1);
        n_test = n_test.max(1);
    }
    let n_train = n - n_val - n_test;
    let mut splits = vec![Split::Test; n];
    for (rank, &index) in order.iter().enumerate() {
        splits[index] = if rank < n_train {
            Split::Train
        } else if rank < n_train + n_val {
            Split::Val
        } else {
            Split::Test
        };
    }
    splits
}

/// The split of one more pair added to a set whose splits number `counts` (train, val, test),
/// for sets that grow one pair at a time and whose pairs must keep their split (the page's
/// export): from the third pair on, validation and then test get one pair first (so a small set
/// can train with early stopping and be evaluated); after that, each pair goes to the split
/// furthest below its 80/10/10 share. Ties go to train, then val.
pub fn next_split(counts: [usize; 3]) -> Split {
    let n = counts.iter().sum::<usize>() + 1;
    if n >= 3 && counts[1] == 0 {
        return Split::Val;
    }
    if n >= 3 && counts[2] == 0 {
        return Split::Test;
    }
    let deficit = |i: usize, share: f64| share * n as f64 - counts[i] as f64;
    let [train, val, test] = [deficit(0, 0.8), deficit(1, 0.1), deficit(2, 0.1)];
    if train >= val && train >= test {
        Split::Train
    } else if val >= test {
        Split::Val
    } else {
        Split::Test
    }
}

/// Above this magnitude (newtons) a tip-force label is implausible for a cardiac catheter: the
/// twin draws contact forces up to 0.4 N and ablation needs 0.1-0.3 N (the paper), so a larger
/// value is most likely a typo or a value in other units (grams-force, millinewtons).
pub const PLAUSIBLE_TIP_FORCE_MAX_N: f32 = 1.0;

/// Why a tip-force label `(Fx, Fy, Fz)` in newtons is implausible, or `None` when it is not.
pub fn implausible_tip_force(force: TipForce) -> Option<String> {
    let magnitude = force.magnitude();
    (magnitude > PLAUSIBLE_TIP_FORCE_MAX_N).then(|| {
        format!(
            "|F| = {magnitude:.3} N is far above a catheter tip's contact forces (at most \
             {PLAUSIBLE_TIP_FORCE_MAX_N} N is expected; ablation needs 0.1-0.3 N): are the \
             values in newtons?"
        )
    })
}

/// One line of the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestRow {
    /// The pair's id (its folder name).
    pub id: String,
    /// Its split.
    pub split: Split,
    /// Tip force `(Fx, Fy, Fz)` in newtons.
    pub force_n: TipForce,
    /// Further columns (the pair's parameters), in column order.
    pub extra: Vec<(String, String)>,
}

impl ManifestRow {
    /// The value of the further column `name`, when the manifest has it.
    pub fn column(&self, name: &str) -> Option<&str> {
        self.extra
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    /// Where its force label came from: [`LabelOrigin::Unrecorded`] when the manifest has no
    /// [`label_origin::ORIGIN_COLUMN`] (older datasets).
    pub fn label_origin(&self) -> Result<LabelOrigin, UnknownOrigin> {
        LabelOrigin::from_columns(|name| self.column(name))
    }
}

/// `dataset.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetHeader {
    /// Always [`FORMAT`].
    pub format: String,
    /// Layout version, [`VERSION`].
    pub version: u32,
    /// Image size in pixels, the same for every image.
    #[serde(deserialize_with = "hnet_units::width_height_or_named")]
    pub image_size: ImageSize,
    /// Number of pairs.
    pub samples: usize,
    /// What made the data and with which settings (free-form JSON: the twin's configuration, the
    /// import's inputs, ...).
    pub source: serde_json::Value,
}

impl DatasetHeader {
    /// A header for `samples` pairs of `image_size` made by `source`.
    pub fn new(image_size: ImageSize, samples: usize, source: serde_json::Value) -> Self {
        Self {
            format: FORMAT.into(),
            version: VERSION,
            image_size,
            samples,
            source,
        }
    }
}

/// A dataset could not be read or written: the file, what is wrong with it, and the error that
/// caused it (an I/O, image, CSV or JSON error) as the [`source`](std::error::Error::source).
#[derive(Debug, thiserror::Error)]
#[error("{}: {problem}", path.display())]
pub struct DatasetError {
    /// The file or folder concerned.
    pub path: PathBuf,
    /// What is wrong with it.
    pub problem: String,
    /// The underlying error, when there is one.
    #[source]
    pub cause: Option<Box<dyn std::error::Error + Send + Sync>>,
}

impl DatasetError {
    /// A problem with `path` that has no underlying error.
    pub fn new(path: impl Into<PathBuf>, problem: impl fmt::Display) -> Self {
        Self {
            path: path.into(),
            problem: problem.to_string(),
            cause: None,
        }
    }

    /// A problem with `path` caused by `cause`.
    pub fn caused_by(
        path: impl Into<PathBuf>,
        problem: impl fmt::Display,
        cause: impl Into<Box<dyn std::error::Error + Send + Sync>>,
    ) -> Self {
        Self {
            path: path.into(),
            problem: problem.to_string(),
            cause: Some(cause.into()),
        }
    }
}

/// Whether `id` is usable as a sample id (and folder name).
pub fn is_valid_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 128
        && !id.starts_with('.')
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// The manifest as CSV bytes. Its further columns are every row's, in the order they are first
/// met; a row without one of them leaves it empty (an export mixing twin pairs and uploads has
/// rows with different columns).
pub fn manifest_csv(rows: &[ManifestRow]) -> Vec<u8> {
    let mut columns: Vec<&str> = Vec::new();
    for (name, _) in rows.iter().flat_map(|row| &row.extra) {
        if !columns.contains(&name.as_str()) {
            columns.push(name);
        }
    }
    let mut out = String::from("id,split,fx,fy,fz");
    for name in &columns {
        out.push(',');
        out.push_str(&csv_field(name));
    }
    out.push('\n');
    for row in rows {
        out.push_str(&csv_field(&row.id));
        out.push(',');
        out.push_str(row.split.name());
        for f in row.force_n.newtons() {
            out.push(',');
            out.push_str(&f.to_string());
        }
        for name in &columns {
            out.push(',');
            out.push_str(&csv_field(row.column(name).unwrap_or_default()));
        }
        out.push('\n');
    }
    out.into_bytes()
}

fn csv_field(value: &str) -> String {
    if value.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", value.replace('"', "\"\""))
    } else {
        value.to_string()
    }
}

/// Parses a manifest; `path` names it in errors. Errors name the offending line.
pub fn parse_manifest(bytes: &[u8], path: &Path) -> Result<Vec<ManifestRow>, DatasetError> {
    let mut reader = csv::ReaderBuilder::new().from_reader(bytes);
    let headers = reader
        .headers()
        .map_err(|e| DatasetError::caused_by(path, "unreadable header line", e))?
        .clone();
    let column = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| DatasetError::new(path, format!("missing column `{name}`")))
    };
    let (id, split) = (column("id")?, column("split")?);
    let forces = [column("fx")?, column("fy")?, column("fz")?];
    let known = [id, split, forces[0], forces[1], forces[2]];
    let mut rows = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for (n, record) in reader.records().enumerate() {
        let line = n + 2;
        let record = record
            .map_err(|e| DatasetError::caused_by(path, format!("line {line} unreadable"), e))?;
        let row_id = record.get(id).unwrap_or_default().to_string();
        if !is_valid_id(&row_id) {
            return Err(DatasetError::new(
                path,
                format!("line {line}: invalid id `{row_id}` (letters, digits, '-', '_', '.')"),
            ));
        }
        if !seen.insert(row_id.clone()) {
            return Err(DatasetError::new(
                path,
                format!("line {line}: duplicate id `{row_id}`"),
            ));
        }
        let split_name = record.get(split).unwrap_or_default();
        let split = Split::parse(split_name).ok_or_else(|| {
            DatasetError::new(
                path,
                format!("line {line}: split `{split_name}` is not train, val or test"),
            )
        })?;
        let mut force_n = [0.0; 3];
        for (axis, (&col, value)) in forces.iter().zip(force_n.iter_mut()).enumerate() {
            let text = record.get(col).unwrap_or_default();
            *value = text
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    DatasetError::new(
                        path,
                        format!(
                            "line {line}: f{} = `{text}` is not a finite number of newtons",
                            ["x", "y", "z"][axis]
                        ),
                    )
                })?;
        }
        let extra = headers
            .iter()
            .enumerate()
            .filter(|(i, _)| !known.contains(i))
            .map(|(i, name)| {
                (
                    name.to_string(),
                    record.get(i).unwrap_or_default().to_string(),
                )
            })
            .collect();
        let row = ManifestRow {
            id: row_id,
            split,
            force_n: TipForce::from_newtons(force_n),
            extra,
        };
        if let Err(e) = row.label_origin() {
            return Err(DatasetError::new(path, format!("line {line}: {e}")));
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Pixels of one image to store.
#[derive(Debug, Clone, Copy)]
pub struct ImageRef<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// `width·height·channels` bytes, row-major.
    pub pixels: &'a [u8],
}

/// Encodes an 8-bit grey or RGB image as PNG (fast deflate; deterministic).
pub fn encode_png(image: ImageRef<'_>) -> Vec<u8> {
    assert_eq!(
        image.pixels.len(),
        image.width * image.height * image.channels,
        "pixel buffer does not match the image size"
    );
    let mut out = Vec::with_capacity(image.pixels.len() / 2 + 1024);
    {
        let mut encoder = png::Encoder::new(&mut out, image.width as u32, image.height as u32);
        encoder.set_color(if image.channels == 3 {
            png::ColorType::Rgb
        } else {
            png::ColorType::Grayscale
        });
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header().expect("writing to memory");
        writer
            .write_image_data(image.pixels)
            .expect("writing to memory");
    }
    out
}

/// The files of one pair: relative paths (inside the dataset folder) and contents, the record
/// last.
pub fn sample_files(
    row: &ManifestRow,
    images: [ImageRef<'_>; 4],
    record: &serde_json::Value,
) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = SAMPLE_IMAGES
        .iter()
        .zip(images)
        .map(|(kind, image)| (image_path(&row.id, kind), encode_png(image)))
        .collect();
    let record = serde_json::json!({ "manifest": row, "record": record });
    files.push((
        record_path(&row.id),
        serde_json::to_vec_pretty(&record).expect("JSON of plain data"),
    ));
    files
}

/// `dataset.json` bytes.
pub fn header_json(header: &DatasetHeader) -> Vec<u8> {
    let mut bytes = serde_json::to_vec_pretty(header).expect("JSON of plain data");
    bytes.push(b'\n');
    bytes
}

#[cfg(not(target_arch = "wasm32"))]
mod folder;

pub mod archive;
#[cfg(not(target_arch = "wasm32"))]
pub mod files;
pub mod force_table;
#[cfg(not(target_arch = "wasm32"))]
pub mod import;
pub mod label_origin;
#[cfg(not(target_arch = "wasm32"))]
pub mod shard;
#[cfg(not(target_arch = "wasm32"))]
pub mod simulate;

#[cfg(not(target_arch = "wasm32"))]
pub use folder::{Dataset, DatasetWriter, LoadedPair};

/// One of the eight symmetries of a square image: `quarter_turns` clockwise quarter turns, then
/// a left-right mirror when `mirrored`. Exact on the pixel grid (no resampling).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SquareSymmetry {
    /// Clockwise quarter turns, 0 to 3.
    pub quarter_turns: u8,
    /// Mirrored left to right after the turns.
    pub mirrored: bool,
}

impl SquareSymmetry {
    /// The symmetry that leaves an image as it is.
    pub const IDENTITY: Self = Self {
        quarter_turns: 0,
        mirrored: false,
    };

    /// Symmetry `index % 8` (`index / 2 % 4` quarter turns, mirrored when `index` is odd): a
    /// uniform draw of `index` is a uniform draw of a symmetry.
    pub fn nth(index: u64) -> Self {
        Self {
            quarter_turns: (index / 2 % 4) as u8,
            mirrored: index % 2 == 1,
        }
    }

    /// `values`, a square image of `size` with `channels` interleaved values per pixel
    /// (row-major), carried by this symmetry: turned by [`hnet_units::turn::turn_clockwise`] (the
    /// network's own turn), then mirrored.
    pub fn apply<T: Copy>(
        self,
        values: &[T],
        size: ImageSize,
        channels: usize,
    ) -> Result<Vec<T>, TurnError> {
        let mut turned = turn_clockwise(values, size, channels, self.quarter_turns)?;
        let row = size.width * channels;
        if self.mirrored && row > 0 {
            for row in turned.chunks_exact_mut(row) {
                // Reversing the row reverses its pixels and each pixel's channels; reversing
                // each pixel again puts its channels back in order.
                row.reverse();
                for pixel in row.chunks_exact_mut(channels) {
                    pixel.reverse();
                }
            }
        }
        Ok(turned)
    }
}

/// The size of a decoded image.
pub fn image_size_of(image: &image::DynamicImage) -> ImageSize {
    ImageSize::new(image.width() as usize, image.height() as usize)
}

/// `image` at `size` (bilinear: the one resize of images, the dataset's, the page's uploads and
/// cine frames), untouched when already there.
pub fn resized(image: image::DynamicImage, size: ImageSize) -> image::DynamicImage {
    if image_size_of(&image) == size {
        image
    } else {
        image.resize_exact(
            size.width as u32,
            size.height as u32,
            image::imageops::FilterType::Triangle,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(id: &str, split: Split) -> ManifestRow {
        ManifestRow {
            id: id.into(),
            split,
            force_n: TipForce::new(0.1, -0.25, 1e-3),
            extra: vec![("note".into(), "a, \"quoted\" value".into())],
        }
    }

    #[test]
    fn splits_are_80_10_10_and_seeded() {
        let s = assign_splits(1000, 42);
        let count = |split| s.iter().filter(|&&x| x == split).count();
        assert_eq!(
            (count(Split::Train), count(Split::Val), count(Split::Test)),
            (800, 100, 100)
        );
        assert_eq!(s, assign_splits(1000, 42));
        assert_ne!(s, assign_splits(1000, 43));
    }

    #[test]
    fn small_sets_keep_a_validation_and_a_test_pair() {
        let count = |n, split| assign_splits(n, 7).iter().filter(|&&x| x == split).count();
        for n in 3..12 {
            assert!(
                count(n, Split::Val) >= 1 && count(n, Split::Test) >= 1,
                "{n}"
            );
            assert!(count(n, Split::Train) >= n / 3, "{n}");
        }
        assert_eq!(count(2, Split::Train), 2);
        assert_eq!(count(1, Split::Train), 1);
    }

    #[test]
    fn pairs_added_one_at_a_time_keep_near_80_10_10() {
        let mut counts = [0usize; 3];
        let mut order = Vec::new();
        for _ in 0..1000 {
            let split = next_split(counts);
            order.push(split);
            counts[split as usize] += 1;
            let n = order.len();
            if n >= 4 {
                assert!(counts[1] >= 1 && counts[2] >= 1, "{n}: {counts:?}");
            }
            for (count, share) in counts.iter().zip([0.8, 0.1, 0.1]) {
                assert!(
                    (*count as f64 - share * n as f64).abs() <= 2.0,
                    "{n}: {counts:?}"
                );
            }
        }
        assert_eq!(counts, [800, 100, 100]);
        assert_eq!(
            &order[..4],
            [Split::Train, Split::Train, Split::Val, Split::Test]
        );
    }

    #[test]
    fn implausible_force_labels_are_named() {
        assert_eq!(implausible_tip_force(TipForce::new(0.3, -0.2, 0.1)), None);
        assert_eq!(implausible_tip_force(TipForce::new(0.0, 0.0, -1.0)), None);
        let why = implausible_tip_force(TipForce::new(5.0, 0.0, 0.0)).unwrap();
        assert!(why.starts_with("|F| = 5.000 N is far above"), "{why}");
    }

    #[test]
    fn the_manifest_round_trips() {
        let rows = vec![row("000001", Split::Train), row("000002", Split::Test)];
        let bytes = manifest_csv(&rows);
        let back = parse_manifest(&bytes, Path::new("m.csv")).unwrap();
        assert_eq!(back, rows);
    }

    #[test]
    fn rows_with_other_columns_share_one_manifest() {
        // An export of a twin pair and an upload: the upload's columns are empty for the twin.
        let twin = ManifestRow {
            extra: vec![("source".into(), "twin".into())],
            ..row("a", Split::Train)
        };
        let upload = ManifestRow {
            extra: vec![
                ("source".into(), "upload".into()),
                ("view_a_file".into(), "x.png".into()),
            ],
            ..row("b", Split::Val)
        };
        let bytes = manifest_csv(&[twin, upload.clone()]);
        let back = parse_manifest(&bytes, Path::new("m.csv")).unwrap();
        assert_eq!(back[0].column("source"), Some("twin"));
        assert_eq!(back[0].column("view_a_file"), Some(""));
        assert_eq!(back[1], upload);
        // An unknown label origin names its line.
        let bad = b"id,split,fx,fy,fz,label_origin\np1,train,0,0,0,guess\n";
        let err = parse_manifest(bad, Path::new("m.csv")).unwrap_err();
        assert!(
            err.to_string().contains("line 2: label_origin `guess`"),
            "{err}"
        );
    }

    #[test]
    fn bad_manifest_lines_are_named() {
        let cases = [
            ("id,split,fx,fy,fz\na,train,0,0,nan\n", "line 2: fz = `nan`"),
            (
                "id,split,fx,fy,fz\na,train,0,0,0\nb,later,0,0,0\n",
                "line 3: split `later`",
            ),
            (
                "id,split,fx,fy,fz\n../x,train,0,0,0\n",
                "line 2: invalid id `../x`",
            ),
            (
                "id,split,fx,fy,fz\na,train,0,0,0\na,val,0,0,0\n",
                "line 3: duplicate id `a`",
            ),
            ("id,split,fx,fy\na,train,0,0\n", "missing column `fz`"),
        ];
        for (text, expected) in cases {
            let err = parse_manifest(text.as_bytes(), Path::new("m.csv")).unwrap_err();
            assert!(err.to_string().starts_with("m.csv: "), "{err}");
            assert!(
                err.to_string().contains(expected),
                "{err} should contain {expected}"
            );
        }
    }

    #[test]
    #[cfg(not(target_arch = "wasm32"))]
    fn the_squares_eight_symmetries_carry_each_mask_with_its_view() {
        // A 3 × 3 view whose nine pixels all differ, its mask the same values over 255.
        let values: Vec<u8> = (0..9).map(|v| 20 * v as u8).collect();
        let pair = LoadedPair {
            size: ImageSize::square(3),
            view_a: values.iter().flat_map(|&v| [v, v, v]).collect(),
            view_b: values.iter().flat_map(|&v| [v, 0, 255 - v]).collect(),
            mask_a: values.iter().map(|&v| f32::from(v) / 255.0).collect(),
            mask_b: values.iter().map(|&v| f32::from(v) / 255.0).collect(),
        };
        let mut seen = std::collections::HashSet::new();
        for index in 0..8 {
            let s = SquareSymmetry::nth(index);
            let turned = pair.clone().with_symmetries([s, SquareSymmetry::IDENTITY]);
            let grey: Vec<u8> = turned.view_a.chunks(3).map(|p| p[0]).collect();
            let mask: Vec<u8> = turned
                .mask_a
                .iter()
                .map(|m| (m * 255.0).round() as u8)
                .collect();
            assert_eq!(
                grey, mask,
                "symmetry {s:?} moved the mask apart from its view"
            );
            assert!(seen.insert(grey), "symmetry {s:?} repeats another");
            assert_eq!(
                (turned.view_b, turned.mask_b),
                (pair.view_b.clone(), pair.mask_b.clone())
            );
        }
        // One clockwise quarter turn takes the top-left pixel to the top-right corner.
        let quarter = SquareSymmetry {
            quarter_turns: 1,
            mirrored: false,
        };
        let turned = pair.clone().with_symmetries([quarter; 2]);
        assert_eq!(turned.view_b[3 * 2..3 * 3], pair.view_b[0..3]);
        // And the bottom-left one to the top-left.
        assert_eq!(turned.mask_a[0], pair.mask_a[6]);
    }

    #[test]
    fn the_squares_symmetries_are_the_image_crates_turns_and_mirror() {
        use image::imageops::{flip_horizontal_in_place, rotate90, rotate180, rotate270};
        let side = 5u32;
        let size = ImageSize::square(side as usize);
        let image = image::RgbImage::from_fn(side, side, |x, y| {
            image::Rgb([(x * 40 + y) as u8, (y * 40 + x) as u8, (x * y) as u8])
        });
        for index in 0..8 {
            let s = SquareSymmetry::nth(index);
            let mut expected = match s.quarter_turns {
                0 => image.clone(),
                1 => rotate90(&image),
                2 => rotate180(&image),
                _ => rotate270(&image),
            };
            if s.mirrored {
                flip_horizontal_in_place(&mut expected);
            }
            assert_eq!(
                s.apply(image.as_raw(), size, 3).unwrap(),
                expected.into_raw(),
                "{s:?}"
            );
        }
        let rgb = image.into_raw();
        assert!(SquareSymmetry::nth(3).apply(&rgb, size, 1).is_err());
        assert!(
            SquareSymmetry::nth(1)
                .apply(&rgb, ImageSize::new(15, 5), 1)
                .is_err()
        );
    }

    #[test]
    fn png_encoding_round_trips() {
        let pixels: Vec<u8> = (0..6 * 4 * 3).map(|v| (v * 7) as u8).collect();
        let png = encode_png(ImageRef {
            width: 6,
            height: 4,
            channels: 3,
            pixels: &pixels,
        });
        let back = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(back.into_raw(), pixels);
    }

    #[test]
    fn ids_are_safe_file_names() {
        assert!(is_valid_id("000123") && is_valid_id("frame_01.b"));
        for bad in ["", ".hidden", "a/b", "a b", "..", "é"] {
            assert!(!is_valid_id(bad), "{bad}");
        }
    }
}
