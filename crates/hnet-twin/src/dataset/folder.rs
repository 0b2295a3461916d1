//! A dataset folder on disk: opening and reading one ([`Dataset`], [`LoadedPair`]) and writing
//! one pair at a time, resumably ([`DatasetWriter`]). Native only; re-exported by
//! [`crate::dataset`].

use super::*;
use std::fs;

fn io(path: &Path, e: std::io::Error) -> DatasetError {
    DatasetError::caused_by(path, "cannot be read or written", e)
}

/// Writes `bytes` to `path` atomically ([`crate::dataset::files::write_atomically`]).
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), DatasetError> {
    crate::dataset::files::write_atomically(path, bytes).map_err(|e| io(path, e))
}

/// Whether the file at `path` is a PNG that was written to its end.
fn png_is_complete(path: &Path) -> bool {
    use std::io::{Read, Seek, SeekFrom};
    let Ok(mut file) = fs::File::open(path) else {
        return false;
    };
    let mut tail = [0u8; 12];
    file.seek(SeekFrom::End(-12)).is_ok() && file.read_exact(&mut tail).is_ok() && tail == PNG_END
}

#[derive(Deserialize)]
struct SampleRecordManifest {
    manifest: ManifestRow,
}

/// The manifest row of pair `id` in `root` if the pair is complete.
fn complete_row(root: &Path, id: &str) -> Option<ManifestRow> {
    let bytes = fs::read(root.join(record_path(id))).ok()?;
    let record: SampleRecordManifest = serde_json::from_slice(&bytes).ok()?;
    SAMPLE_IMAGES
        .iter()
        .all(|kind| png_is_complete(&root.join(image_path(id, kind))))
        .then_some(record.manifest)
}

/// `header` with a simulated set's twin settings (`source.twin`) spelled as this version writes
/// them, so that a simulation started before a setting's spelling changed (`image_size`, once a
/// bare side) still resumes.
fn respelled(mut header: DatasetHeader) -> DatasetHeader {
    use crate::simulator::scene::TwinConfig;
    if let Some(twin) = header.source.get_mut("twin")
        && let Ok(config) = serde_json::from_value::<TwinConfig>(twin.clone())
        && let Ok(value) = serde_json::to_value(config)
    {
        *twin = value;
    }
    header
}

/// Writes a dataset folder sample by sample, crash-safely, and resumes an interrupted one.
#[derive(Debug)]
pub struct DatasetWriter {
    root: PathBuf,
}

impl DatasetWriter {
    /// Opens `root` for writing the dataset described by `header`.
    ///
    /// A missing or empty folder is created. A folder holding the same dataset (an equal
    /// header) is resumed. Anything else is refused, so that nothing already there is
    /// overwritten.
    pub fn create_or_resume(root: &Path, header: &DatasetHeader) -> Result<Self, DatasetError> {
        let header_path = root.join(HEADER_FILE);
        if header_path.exists() {
            let bytes = fs::read(&header_path).map_err(|e| io(&header_path, e))?;
            let existing: DatasetHeader = serde_json::from_slice(&bytes)
                .map_err(|e| DatasetError::caused_by(&header_path, "not a dataset header", e))?;
            if respelled(existing) != respelled(header.clone()) {
                return Err(DatasetError::new(
                    root,
                    "holds a dataset made with other settings; choose another output \
                     folder, or repeat the original command to resume it",
                ));
            }
        } else {
            if root.exists() {
                let mut entries = fs::read_dir(root).map_err(|e| io(root, e))?;
                if entries.next().is_some() {
                    return Err(DatasetError::new(
                        root,
                        "exists and is not empty (and is not a dataset); refusing to write into it",
                    ));
                }
            }
            fs::create_dir_all(root.join(SAMPLES_DIR)).map_err(|e| io(root, e))?;
            write_atomically(&header_path, &header_json(header))?;
        }
        fs::create_dir_all(root.join(SAMPLES_DIR)).map_err(|e| io(root, e))?;
        Ok(Self {
            root: root.to_path_buf(),
        })
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Whether the pair `id` is already complete (written by an earlier run).
    pub fn has_sample(&self, id: &str) -> bool {
        complete_row(&self.root, id).is_some()
    }

    /// Writes one pair's files (from [`sample_files`]: its images, then its record).
    pub fn write_sample(&self, id: &str, files: &[(String, Vec<u8>)]) -> Result<(), DatasetError> {
        let record = record_path(id);
        if files.last().map(|(path, _)| path) != Some(&record) {
            return Err(DatasetError::new(
                self.root.join(&record),
                "a pair's record must be its last file",
            ));
        }
        // An earlier, interrupted attempt must not pass for complete while this one writes.
        let record_file = self.root.join(&record);
        if record_file.exists() {
            fs::remove_file(&record_file).map_err(|e| io(&record_file, e))?;
        }
        let prefix = format!("{SAMPLES_DIR}/{id}");
        for (path, bytes) in files {
            if !path.starts_with(&prefix) || path.contains("..") {
                return Err(DatasetError::new(
                    self.root.join(path),
                    format!("is not a file of pair `{id}`"),
                ));
            }
            let target = self.root.join(path);
            fs::write(&target, bytes).map_err(|e| io(&target, e))?;
        }
        Ok(())
    }

    /// Writes the manifest from every complete pair, sorted by id, and removes what
    /// incomplete pairs left behind. Returns the rows.
    pub fn finish(&self) -> Result<Vec<ManifestRow>, DatasetError> {
        let samples = self.root.join(SAMPLES_DIR);
        let mut names: Vec<String> = fs::read_dir(&samples)
            .map_err(|e| io(&samples, e))?
            .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
            .collect::<Result<_, _>>()
            .map_err(|e| io(&samples, e))?;
        names.sort();
        for name in names.iter().filter(|n| n.ends_with(".partial")) {
            let path = samples.join(name);
            fs::remove_file(&path).map_err(|e| io(&path, e))?;
        }
        let ids: std::collections::BTreeSet<String> = names
            .iter()
            .filter_map(|n| {
                n.strip_suffix(".json").map(str::to_string).or_else(|| {
                    SAMPLE_IMAGES
                        .iter()
                        .find_map(|k| n.strip_suffix(&format!("_{k}.png")))
                        .map(str::to_string)
                })
            })
            .collect();
        let mut rows = Vec::new();
        for id in ids {
            match complete_row(&self.root, &id) {
                Some(row) => rows.push(row),
                None => {
                    for path in SAMPLE_IMAGES
                        .iter()
                        .map(|k| image_path(&id, k))
                        .chain([record_path(&id)])
                    {
                        let path = self.root.join(path);
                        if path.exists() {
                            fs::remove_file(&path).map_err(|e| io(&path, e))?;
                        }
                    }
                }
            }
        }
        write_atomically(&self.root.join(MANIFEST_FILE), &manifest_csv(&rows))?;
        Ok(rows)
    }
}

/// A dataset opened for reading.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Its folder.
    pub root: PathBuf,
    /// `dataset.json`.
    pub header: DatasetHeader,
    /// `manifest.csv`.
    pub rows: Vec<ManifestRow>,
}

/// One pair's decoded images as 8-bit RGB and its masks as probabilities.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedPair {
    /// The size of all four images.
    pub size: ImageSize,
    /// View A, RGB.
    pub view_a: Vec<u8>,
    /// View B, RGB.
    pub view_b: Vec<u8>,
    /// Mask A in `[0, 1]`.
    pub mask_a: Vec<f32>,
    /// Mask B in `[0, 1]`.
    pub mask_b: Vec<f32>,
}

impl Dataset {
    /// Opens the dataset in `root`, checking its header and manifest.
    pub fn open(root: &Path) -> Result<Self, DatasetError> {
        let header_path = root.join(HEADER_FILE);
        let bytes = fs::read(&header_path).map_err(|e| {
            DatasetError::caused_by(
                &header_path,
                format!(
                    "cannot be read (is {} an H-Net Studio dataset?)",
                    root.display()
                ),
                e,
            )
        })?;
        let header: DatasetHeader = serde_json::from_slice(&bytes)
            .map_err(|e| DatasetError::caused_by(&header_path, "not a dataset header", e))?;
        if header.format != FORMAT {
            return Err(DatasetError::new(
                &header_path,
                format!("format is `{}`, expected `{FORMAT}`", header.format),
            ));
        }
        if header.version != VERSION {
            return Err(DatasetError::new(
                &header_path,
                format!(
                    "format version {} is not supported (this build reads version {VERSION})",
                    header.version
                ),
            ));
        }
        let manifest_path = root.join(MANIFEST_FILE);
        let bytes = fs::read(&manifest_path).map_err(|e| {
            DatasetError::caused_by(
                &manifest_path,
                "cannot be read (an interrupted generation writes it when resumed and finished)",
                e,
            )
        })?;
        let rows = parse_manifest(&bytes, &manifest_path)?;
        Ok(Self {
            root: root.to_path_buf(),
            header,
            rows,
        })
    }

    /// The rows of one split.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &ManifestRow> {
        self.rows.iter().filter(move |r| r.split == split)
    }

    /// Path of one of a pair's images (`kind` from [`SAMPLE_IMAGES`]).
    pub fn image_file(&self, id: &str, kind: &str) -> PathBuf {
        self.root.join(image_path(id, kind))
    }

    /// Path of a pair's record.
    pub fn record_file(&self, id: &str) -> PathBuf {
        self.root.join(record_path(id))
    }

    /// Decodes a pair, resized to `size` when given.
    pub fn load_pair(
        &self,
        row: &ManifestRow,
        size: Option<ImageSize>,
    ) -> Result<LoadedPair, DatasetError> {
        let load = |kind: &str| -> Result<image::DynamicImage, DatasetError> {
            let path = self.image_file(&row.id, kind);
            let bytes = fs::read(&path).map_err(|e| io(&path, e))?;
            image::load_from_memory(&bytes)
                .map_err(|e| DatasetError::caused_by(&path, "unreadable image", e))
        };
        let [a, b, ma, mb] = SAMPLE_IMAGES.map(load);
        let (a, b, ma, mb) = (a?, b?, ma?, mb?);
        let first = image_size_of(&a);
        for (kind, img) in SAMPLE_IMAGES.iter().zip([&a, &b, &ma, &mb]) {
            let found = image_size_of(img);
            if found != first {
                return Err(DatasetError::new(
                    self.image_file(&row.id, kind),
                    format!(
                        "is {found} but {} is {first}",
                        image_path(&row.id, SAMPLE_IMAGES[0]),
                    ),
                ));
            }
        }
        Ok(LoadedPair::of_images([a, b, ma, mb], size.unwrap_or(first)))
    }
}

impl LoadedPair {
    /// Views A and B and masks A and B, all of one size, at `size`: the one conversion of
    /// a pair for a network, whether it was read from files or rendered just now.
    pub fn of_images(images: [image::DynamicImage; 4], size: ImageSize) -> Self {
        let [a, b, ma, mb] = images;
        let resize = |img: image::DynamicImage| resized(img, size);
        let mask = |img: image::DynamicImage| -> Vec<f32> {
            resize(img)
                .to_luma8()
                .into_raw()
                .into_iter()
                .map(|v| f32::from(v) / 255.0)
                .collect()
        };
        LoadedPair {
            size,
            view_a: resize(a).to_rgb8().into_raw(),
            view_b: resize(b).to_rgb8().into_raw(),
            mask_a: mask(ma),
            mask_b: mask(mb),
        }
    }

    /// The pair with each view, image and mask together, carried by its symmetry of the
    /// square (`[a, b]`). The views' pixels no longer come from their C-arm's projection, so
    /// such a pair may teach masks but not force. Square pairs only.
    pub fn with_symmetries(self, [a, b]: [SquareSymmetry; 2]) -> Self {
        assert_eq!(
            self.size.width, self.size.height,
            "the square's symmetries need a square pair"
        );
        let size = self.size;
        let rgb = |pixels: Vec<u8>, s: SquareSymmetry| {
            s.apply(&pixels, size, 3)
                .expect("a loaded view holds size × size RGB pixels")
        };
        let mask = |pixels: Vec<f32>, s: SquareSymmetry| {
            s.apply(&pixels, size, 1)
                .expect("a loaded mask holds size × size values")
        };
        LoadedPair {
            size: self.size,
            view_a: rgb(self.view_a, a),
            view_b: rgb(self.view_b, b),
            mask_a: mask(self.mask_a, a),
            mask_b: mask(self.mask_b, b),
        }
    }

    /// A twin sample rendered at `rendered` as [`Dataset::load_pair`] would read it
    /// back from the files [`crate::dataset::simulate::simulated_sample_files`] writes (lossless
    /// PNG), at `size`: training on samples made on the fly sees the same pixels as
    /// training on a simulated dataset.
    pub fn from_sample(
        sample: &crate::simulator::scene::StereoSample,
        rendered: ImageSize,
        size: ImageSize,
    ) -> Self {
        use crate::simulator::scene::ViewPixels;
        let (width, height) = (rendered.width as u32, rendered.height as u32);
        let view = |pixels: &ViewPixels| -> image::DynamicImage {
            match pixels {
                ViewPixels::Grey(g) => image::GrayImage::from_raw(width, height, g.clone())
                    .map(image::DynamicImage::ImageLuma8),
                ViewPixels::Rgb(c) => image::RgbImage::from_raw(width, height, c.clone())
                    .map(image::DynamicImage::ImageRgb8),
            }
            .expect("a rendered view has the twin's image size")
        };
        let mask = |m: &Vec<u8>| -> image::DynamicImage {
            image::GrayImage::from_raw(width, height, m.clone())
                .map(image::DynamicImage::ImageLuma8)
                .expect("a rendered mask has the twin's image size")
        };
        let [a, b] = &sample.views;
        Self::of_images(
            [
                view(&a.pixels),
                view(&b.pixels),
                mask(&a.mask),
                mask(&b.mask),
            ],
            size,
        )
    }
}
