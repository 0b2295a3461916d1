//! Training pairs to batches of tensors: a dataset's split read from disk, or pairs the twin
//! makes on the fly ([`twin_stream`]).
//!
//! A split is decoded, resized to the model's input size and kept in memory as bytes
//! ([`pair_bytes`] per pair), so that epochs after the first cost no PNG decoding; a training
//! split too large for that is read from disk as the loader asks ([`DiskSplit`]), so that
//! memory does not grow with the dataset.

pub mod twin_stream;

use std::sync::Arc;

use anyhow::Context;
use burn::data::dataloader::batcher::Batcher;
use burn::data::dataset::{Dataset as BurnDataset, DatasetError};
use burn::tensor::Device;
use hnet_model::training::{LabelledPair, TrainingBatch};
use hnet_twin::dataset::label_origin::LabelFilter;
use hnet_twin::dataset::{Dataset, LoadedPair, ManifestRow, Split, SquareSymmetry};
use hnet_units::ImageSize;
use hnet_units::TipForce;
use rayon::prelude::*;

/// One stereo pair at the model's input size.
#[derive(Debug, Clone)]
pub struct StereoItem {
    /// View A, RGB bytes, `H·W·3`.
    pub view_a: Arc<[u8]>,
    /// View B, RGB bytes.
    pub view_b: Arc<[u8]>,
    /// Mask A, coverage bytes (255 = catheter), `H·W`.
    pub mask_a: Arc<[u8]>,
    /// Mask B.
    pub mask_b: Arc<[u8]>,
    /// Tip force in newtons.
    pub force_n: TipForce,
    /// Whether the force is a label to learn from; off-bench pairs of a stream carry masks
    /// only (see [`twin_stream`]).
    pub force_known: bool,
    /// The pair's id.
    pub id: Arc<str>,
}

impl StereoItem {
    /// A pair as the network reads it, with its tip force in newtons.
    pub fn new(pair: LoadedPair, force_n: TipForce, force_known: bool, id: String) -> Self {
        let mask =
            |m: &[f32]| -> Arc<[u8]> { m.iter().map(|v| (v * 255.0).round() as u8).collect() };
        Self {
            view_a: pair.view_a.into(),
            view_b: pair.view_b.into(),
            mask_a: mask(&pair.mask_a),
            mask_b: mask(&pair.mask_b),
            force_n,
            force_known,
            id: id.into(),
        }
    }
}

/// Bytes one pair takes in memory at `size`: both views (RGB) and both masks, a byte each.
pub fn pair_bytes(size: ImageSize) -> usize {
    2 * (3 + 1) * size.pixels()
}

/// The pairs of one split, read from disk pair by pair as the loader asks (decoded and resized
/// every epoch): its memory is the manifest rows, whatever the number of pairs.
#[derive(Debug, Clone)]
pub struct DiskSplit {
    dataset: Arc<Dataset>,
    rows: Vec<ManifestRow>,
    size: ImageSize,
    labels: LabelFilter,
}

impl DiskSplit {
    /// `split` of `dataset` at `size`, at most `limit` pairs.
    pub fn new(dataset: &Dataset, split: Split, size: ImageSize, limit: Option<usize>) -> Self {
        Self {
            rows: dataset
                .split(split)
                .take(limit.unwrap_or(usize::MAX))
                .cloned()
                .collect(),
            dataset: Arc::new(dataset.clone()),
            size,
            labels: LabelFilter::all(),
        }
    }

    /// Only force labels `labels` admits teach the force head; the other pairs train their
    /// masks alone.
    pub fn with_labels(self, labels: LabelFilter) -> Self {
        Self { labels, ..self }
    }
}

/// Whether `row`'s force label may train the force head under `labels`.
pub fn force_label_admitted(row: &ManifestRow, labels: &LabelFilter) -> bool {
    // The manifest's reader refused unknown origins already.
    labels.admits(&row.label_origin().unwrap_or_default())
}

impl BurnDataset<StereoItem> for DiskSplit {
    fn get(&self, index: usize) -> Result<StereoItem, DatasetError> {
        let row = self.rows.get(index).ok_or_else(|| {
            DatasetError::new(std::io::Error::other(format!(
                "pair {index} of {} requested",
                self.rows.len()
            )))
        })?;
        let pair = self
            .dataset
            .load_pair(row, Some(self.size))
            .map_err(DatasetError::new)?;
        let known = force_label_admitted(row, &self.labels);
        Ok(StereoItem::new(pair, row.force_n, known, row.id.clone()))
    }

    fn len(&self) -> usize {
        self.rows.len()
    }
}

/// The pairs of one split, in memory.
#[derive(Debug, Clone)]
pub struct StereoSplit {
    /// The pairs, in manifest order.
    pub items: Vec<StereoItem>,
}

impl StereoSplit {
    /// Loads `split` of `dataset` at `size`, at most `limit` pairs.
    pub fn load(
        dataset: &Dataset,
        split: Split,
        size: ImageSize,
        limit: Option<usize>,
    ) -> anyhow::Result<Self> {
        Self::load_turned(dataset, split, size, limit, SquareSymmetry::IDENTITY)
    }

    /// [`Self::load`] with both views of every pair, each with its label mask, carried by
    /// `symmetry` ([`LoadedPair::with_symmetries`]; square sizes only, unless the identity).
    pub fn load_turned(
        dataset: &Dataset,
        split: Split,
        size: ImageSize,
        limit: Option<usize>,
        symmetry: SquareSymmetry,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(
            symmetry == SquareSymmetry::IDENTITY || size.width == size.height,
            "views can only be turned at a square size, not {size}"
        );
        let rows: Vec<&ManifestRow> = dataset
            .split(split)
            .take(limit.unwrap_or(usize::MAX))
            .collect();
        let items = rows
            .par_iter()
            .map(|row| -> anyhow::Result<StereoItem> {
                let mut pair = dataset.load_pair(row, Some(size))?;
                if symmetry != SquareSymmetry::IDENTITY {
                    pair = pair.with_symmetries([symmetry; 2]);
                }
                Ok(StereoItem::new(pair, row.force_n, true, row.id.clone()))
            })
            .collect::<anyhow::Result<Vec<_>>>()
            .with_context(|| {
                format!(
                    "loading the {} split of {}",
                    split.name(),
                    dataset.root.display()
                )
            })?;
        Ok(Self { items })
    }

    /// Keeps only the force labels `labels` admits as labels to learn from (the others' pairs
    /// train their masks alone); returns how many were left out.
    pub fn admit_force_labels(&mut self, dataset: &Dataset, labels: &LabelFilter) -> usize {
        let admitted: std::collections::HashMap<&str, bool> = dataset
            .rows
            .iter()
            .map(|row| (row.id.as_str(), force_label_admitted(row, labels)))
            .collect();
        let mut left_out = 0;
        for item in &mut self.items {
            if item.force_known && !admitted.get(&*item.id).copied().unwrap_or(true) {
                item.force_known = false;
                left_out += 1;
            }
        }
        left_out
    }
}

impl BurnDataset<StereoItem> for StereoSplit {
    fn get(&self, index: usize) -> Result<StereoItem, DatasetError> {
        self.items.get(index).cloned().ok_or_else(|| {
            DatasetError::new(std::io::Error::other(format!(
                "pair {index} of {} requested",
                self.items.len()
            )))
        })
    }

    fn len(&self) -> usize {
        self.items.len()
    }
}

/// Turns pairs into [`TrainingBatch`]es (the one batch of `hnet train` and the page's
/// fine-tuning).
#[derive(Debug, Clone)]
pub struct StereoBatcher {
    /// The images' size.
    pub size: ImageSize,
}

impl Batcher<StereoItem, TrainingBatch> for StereoBatcher {
    fn batch(&self, items: Vec<StereoItem>, device: &Device) -> TrainingBatch {
        let pairs: Vec<LabelledPair<'_>> = items
            .iter()
            .map(|item| LabelledPair {
                view_a: &item.view_a,
                view_b: &item.view_b,
                mask_a: &item.mask_a,
                mask_b: &item.mask_b,
                force_n: item.force_known.then_some(item.force_n),
            })
            .collect();
        // Every item was decoded at the batcher's size (StereoSplit, DiskSplit, TwinStream).
        TrainingBatch::of(&pairs, self.size, device)
            .unwrap_or_else(|e| panic!("a training pair was decoded at another size: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Tensor;
    use hnet_twin::dataset::{DatasetHeader, DatasetWriter, ImageRef, sample_files};

    /// A non-square dataset (48 wide, 32 high) with one marked pixel reaches the network's
    /// `[B, C, H, W]` tensors at the same place: the dataset's sizes are `[width, height]`, the
    /// model's `[height, width]`, and nothing else in the suite uses other than square images.
    #[test]
    fn non_square_pairs_keep_their_orientation() {
        let (width, height, marker) = (48usize, 32usize, (40usize, 5usize));
        let root = std::env::temp_dir().join(format!("hnet-non-square-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let header = DatasetHeader::new(ImageSize::new(width, height), 1, serde_json::json!({}));
        let writer = DatasetWriter::create_or_resume(&root, &header).unwrap();
        let mut rgb = vec![0u8; width * height * 3];
        let mut grey = vec![0u8; width * height];
        let at = marker.1 * width + marker.0;
        rgb[at * 3..at * 3 + 3].copy_from_slice(&[255, 255, 255]);
        grey[at] = 255;
        let rgb_image = ImageRef {
            width,
            height,
            channels: 3,
            pixels: &rgb,
        };
        let mask_image = ImageRef {
            channels: 1,
            pixels: &grey,
            ..rgb_image
        };
        let row = ManifestRow {
            id: "wide".into(),
            split: Split::Train,
            force_n: TipForce::new(0.1, 0.0, 0.0),
            extra: Vec::new(),
        };
        let images = [rgb_image, rgb_image, mask_image, mask_image];
        writer
            .write_sample(&row.id, &sample_files(&row, images, &serde_json::json!({})))
            .unwrap();
        writer.finish().unwrap();

        let dataset = Dataset::open(&root).unwrap();
        let model_size = ImageSize::new(width, height);
        let split = StereoSplit::load(&dataset, Split::Train, model_size, None).unwrap();
        assert_eq!(split.items[0].mask_a[at], 255);
        let batch = StereoBatcher { size: model_size }.batch(split.items, &Device::flex());
        assert_eq!(batch.view_a.dims(), [1, 3, height, width]);
        let value = |t: &Tensor<4>, c: usize| {
            let pixel = t.clone().slice([
                0..1,
                c..c + 1,
                marker.1..marker.1 + 1,
                marker.0..marker.0 + 1,
            ]);
            hnet_model::inference::host_values(pixel).unwrap()[0]
        };
        assert_eq!(value(&batch.view_a, 2), 1.0);
        assert_eq!(value(&batch.mask_b, 0), 1.0);
        std::fs::remove_dir_all(root).ok();
    }
}
