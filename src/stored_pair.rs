//! A pair as the page stores it in the browser (IndexedDB, [`crate::storage`]): its metadata as
//! JSON and its two views and two masks as PNGs, each under its own key; and reading such a
//! record back, which refuses anything that is not what this page writes (the record may come
//! from another version of the page, or be damaged) with a [`DamagedRecord`], never a panic.
//!
//! Kept apart from the IndexedDB calls so that the format is tested natively, with property
//! tests, as well as in the browser.

use hnet_twin::dataset::label_origin::LabelOrigin;
use hnet_twin::dataset::{ImageRef, Split, encode_png};
use hnet_units::{ImageSize, TipForce};

use crate::imaging::WORK_SIZE;
use crate::workspace::{LabeledPair, PairSource};

/// The keys of a record's images and masks, with their channels (RGB views, grey masks).
pub const IMAGE_KEYS: [(&str, usize); 4] =
    [("view_a", 3), ("view_b", 3), ("mask_a", 1), ("mask_b", 1)];

/// The key of a record's metadata (JSON).
pub const METADATA_KEY: &str = "metadata";

/// What a record's metadata holds.
#[derive(serde::Serialize, serde::Deserialize)]
struct Metadata {
    id: String,
    source: PairSource,
    masks_labeled: bool,
    force_n: Option<TipForce>,
    /// Absent in records saved before label origins were kept (read as unrecorded).
    #[serde(default)]
    force_origin: LabelOrigin,
    /// Absent in records saved before views could be marked as showing no catheter.
    #[serde(default)]
    no_catheter: [bool; 2],
    /// Absent in records saved before splits were kept (they get one at the next export).
    #[serde(default)]
    split: Option<Split>,
}

/// A saved record that cannot be read back as a pair: it is skipped (and left in storage).
#[derive(Debug, thiserror::Error)]
pub enum DamagedRecord {
    /// It has no metadata.
    #[error("a stored pair has no metadata")]
    NoMetadata,
    /// Its metadata is not what this page writes.
    #[error("a stored pair's metadata cannot be read")]
    Metadata(#[source] serde_json::Error),
    /// An image or mask is missing.
    #[error("stored pair {id} lacks `{key}`")]
    Missing {
        /// The pair.
        id: String,
        /// The image's key.
        key: &'static str,
    },
    /// An image or mask is not a PNG.
    #[error("stored pair {id}: `{key}` is damaged")]
    Image {
        /// The pair.
        id: String,
        /// The image's key.
        key: &'static str,
        /// The decoder's error.
        #[source]
        cause: image::ImageError,
    },
    /// An image or mask is a PNG of another size than the page works at.
    #[error(
        "stored pair {id}: `{key}` is {width} x {height} pixels, not {} x {}",
        WORK_SIZE.width,
        WORK_SIZE.height
    )]
    Size {
        /// The pair.
        id: String,
        /// The image's key.
        key: &'static str,
        /// Its width, pixels.
        width: u32,
        /// Its height, pixels.
        height: u32,
    },
}

/// A pair's metadata as stored: JSON.
pub fn metadata_json(pair: &LabeledPair) -> Result<String, serde_json::Error> {
    serde_json::to_string(&Metadata {
        id: pair.id.clone(),
        source: pair.source.clone(),
        masks_labeled: pair.masks_labeled,
        force_n: pair.force_n,
        force_origin: pair.force_origin.clone(),
        no_catheter: pair.no_catheter,
        split: pair.split,
    })
}

/// A pair's images and masks as stored, in the order of [`IMAGE_KEYS`]: PNGs.
pub fn image_pngs(pair: &LabeledPair) -> [Vec<u8>; 4] {
    let pixels = [&pair.view_a, &pair.view_b, &pair.mask_a, &pair.mask_b];
    core::array::from_fn(|i| {
        encode_png(ImageRef {
            width: WORK_SIZE.width,
            height: WORK_SIZE.height,
            channels: IMAGE_KEYS[i].1,
            pixels: pixels[i],
        })
    })
}

/// Largest allocation one stored PNG may make while decoding: a 224 px RGB image needs 150 KiB;
/// a damaged header may claim far more.
const MAX_DECODE_BYTES: u64 = 16 * 1024 * 1024;

/// The image or mask `key` (with `channels`) of the stored pair `id`, from its PNG `bytes`.
fn decode(
    bytes: Option<&[u8]>,
    id: &str,
    key: &'static str,
    channels: usize,
) -> Result<Vec<u8>, DamagedRecord> {
    let bytes = bytes.ok_or_else(|| DamagedRecord::Missing {
        id: id.to_string(),
        key,
    })?;
    let damaged = |cause| DamagedRecord::Image {
        id: id.to_string(),
        key,
        cause,
    };
    let mut reader =
        image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    reader.limits(limits);
    let image = reader.decode().map_err(damaged)?;
    if ImageSize::new(image.width() as usize, image.height() as usize) != WORK_SIZE {
        return Err(DamagedRecord::Size {
            id: id.to_string(),
            key,
            width: image.width(),
            height: image.height(),
        });
    }
    Ok(if channels == 3 {
        image.to_rgb8().into_raw()
    } else {
        image.to_luma8().into_raw()
    })
}

/// A stored record as a pair, from its metadata (`None` when the record has none) and its
/// images by key (`None` for a key it lacks).
pub fn read_record<'a>(
    metadata: Option<&str>,
    image: impl Fn(&'static str) -> Option<&'a [u8]>,
) -> Result<LabeledPair, DamagedRecord> {
    let metadata: Metadata = serde_json::from_str(metadata.ok_or(DamagedRecord::NoMetadata)?)
        .map_err(DamagedRecord::Metadata)?;
    let id = &metadata.id;
    let [view_a, view_b, mask_a, mask_b] = [0, 1, 2, 3].map(|i| {
        let (key, channels) = IMAGE_KEYS[i];
        decode(image(key), id, key, channels)
    });
    Ok(LabeledPair {
        view_a: view_a?,
        view_b: view_b?,
        mask_a: mask_a?,
        mask_b: mask_b?,
        id: metadata.id,
        source: metadata.source,
        masks_labeled: metadata.masks_labeled,
        force_n: metadata.force_n,
        force_origin: metadata.force_origin,
        no_catheter: metadata.no_catheter,
        split: metadata.split,
    })
}

// Property tests (issue #13, docs/reliability.md): whatever pair the page stores reads back
// exactly; whatever bytes a record holds (arbitrary, or a valid record mutated), reading it
// gives a pair or a `DamagedRecord`, never a panic or an unbounded allocation.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod properties {
    use super::*;
    use crate::export::properties::pair;
    use crate::imaging::properties::cases;
    use hnet_mutations::{edits, mutate};
    use proptest::prelude::*;

    fn read(metadata: &str, images: &[Vec<u8>; 4]) -> Result<LabeledPair, DamagedRecord> {
        read_record(Some(metadata), |key| {
            let i = IMAGE_KEYS.iter().position(|(k, _)| *k == key)?;
            Some(images[i].as_slice())
        })
    }

    proptest! {
        #![proptest_config(cases(32))]

        #[test]
        fn stored_pairs_read_back_exactly(pair in pair()) {
            let back = read(&metadata_json(&pair).unwrap(), &image_pngs(&pair)).unwrap();
            prop_assert_eq!(back, pair);
        }

        #[test]
        fn mutated_records_are_refused_or_read_never_a_panic(
            pair in pair(),
            metadata_edits in edits(),
            image_edits in proptest::collection::vec((0usize..4, edits()), 0..4),
        ) {
            let metadata = mutate(metadata_json(&pair).unwrap().into_bytes(), &metadata_edits);
            let mut images = image_pngs(&pair);
            for (i, edits) in image_edits {
                images[i] = mutate(core::mem::take(&mut images[i]), &edits);
            }
            let metadata = String::from_utf8_lossy(&metadata);
            if let Ok(back) = read(&metadata, &images) {
                for (pixels, (_, channels)) in
                    [&back.view_a, &back.view_b, &back.mask_a, &back.mask_b].iter().zip(IMAGE_KEYS)
                {
                    prop_assert_eq!(pixels.len(), WORK_SIZE.pixels() * channels);
                }
            }
        }

        #[test]
        fn arbitrary_records_are_refused_never_a_panic(
            metadata in proptest::option::of("\\PC{0,64}"),
            images in proptest::collection::vec(
                proptest::option::of(proptest::collection::vec(any::<u8>(), 0..128)), 4),
        ) {
            let _ = read_record(metadata.as_deref(), |key| {
                let i = IMAGE_KEYS.iter().position(|(k, _)| *k == key)?;
                images[i].as_deref()
            });
        }
    }

    /// A PNG of another size, or one whose header claims a huge image, is named, not read.
    #[test]
    fn images_of_another_size_or_claiming_huge_sizes_are_refused() {
        let pair = crate::twin_live::TwinControls::default()
            .render(
                "stored-1".into(),
                &crate::twin_live::XrayBackground::phantom(),
            )
            .unwrap();
        let mut images = image_pngs(&pair);
        images[2] = encode_png(ImageRef {
            width: 10,
            height: 12,
            channels: 1,
            pixels: &[0; 120],
        });
        let metadata = metadata_json(&pair).unwrap();
        let error = read(&metadata, &images).unwrap_err();
        assert!(
            error
                .to_string()
                .ends_with("`mask_a` is 10 x 12 pixels, not 224 x 224"),
            "{error}"
        );
        // IHDR width and height (bytes 16..24) claim 60000 x 60000 (the chunk's CRC is
        // rewritten so that the decoder reads the header).
        let mut huge = image_pngs(&pair)[0].clone();
        huge[16..24].copy_from_slice(&[0, 0, 0xEA, 0x60, 0, 0, 0xEA, 0x60]);
        let crc = crc32fast::hash(&huge[12..29]);
        huge[29..33].copy_from_slice(&crc.to_be_bytes());
        images = image_pngs(&pair);
        images[0] = huge;
        match read(&metadata, &images) {
            Err(DamagedRecord::Image {
                key: "view_a",
                cause: image::ImageError::Limits(_),
                ..
            }) => {}
            other => panic!("{other:?}"),
        }
    }
}
