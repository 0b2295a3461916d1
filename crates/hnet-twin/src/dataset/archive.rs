//! A dataset as one zip file, in exactly the folder layout of [`crate::dataset`]: what the
//! browser app exports. Unzipped, it is a dataset `hnet train` reads.
//!
//! Entries are stored uncompressed: the PNG images already are compressed, and the rest is small.

use std::io::{Cursor, Write};

use zip::ZipWriter;
use zip::write::SimpleFileOptions;

use crate::dataset::{
    DatasetHeader, HEADER_FILE, ImageRef, MANIFEST_FILE, ManifestRow, header_json, manifest_csv,
    sample_files,
};

/// Builds a dataset zip in memory.
pub struct DatasetArchive {
    zip: ZipWriter<Cursor<Vec<u8>>>,
    rows: Vec<ManifestRow>,
    folder: String,
}

/// Writing to memory cannot fail for lack of space; a failure here is a bug in the archive's use
/// (such as a duplicate pair id).
#[derive(Debug, thiserror::Error)]
#[error("cannot build the dataset archive")]
pub struct ArchiveError(#[from] zip::result::ZipError);

impl DatasetArchive {
    /// An empty archive whose entries sit in the folder `folder` (the dataset's name).
    pub fn new(folder: &str) -> Self {
        Self {
            zip: ZipWriter::new(Cursor::new(Vec::new())),
            rows: Vec::new(),
            folder: folder.trim_matches('/').to_string(),
        }
    }

    fn add(&mut self, path: &str, bytes: &[u8]) -> Result<(), ArchiveError> {
        let options = SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            // A fixed time stamp keeps archives of the same data byte-identical.
            .last_modified_time(zip::DateTime::default());
        self.zip
            .start_file(format!("{}/{path}", self.folder), options)
            .map_err(ArchiveError)?;
        self.zip
            .write_all(bytes)
            .map_err(|e| ArchiveError(e.into()))
    }

    /// Adds one pair: its manifest row, its four images and its record.
    pub fn add_pair(
        &mut self,
        row: ManifestRow,
        images: [ImageRef<'_>; 4],
        record: &serde_json::Value,
    ) -> Result<(), ArchiveError> {
        for (path, bytes) in sample_files(&row, images, record) {
            self.add(&path, &bytes)?;
        }
        self.rows.push(row);
        Ok(())
    }

    /// Writes the header and the manifest and returns the zip's bytes.
    pub fn finish(mut self, header: &DatasetHeader) -> Result<Vec<u8>, ArchiveError> {
        self.rows.sort_by(|a, b| a.id.cmp(&b.id));
        let manifest = manifest_csv(&self.rows);
        self.add(HEADER_FILE, &header_json(header))?;
        self.add(MANIFEST_FILE, &manifest)?;
        let cursor = self.zip.finish().map_err(ArchiveError)?;
        Ok(cursor.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{Dataset, Split};

    #[test]
    fn an_archive_unzips_into_a_readable_dataset() {
        let mut archive = DatasetArchive::new("labels");
        let pixels = vec![100u8; 8 * 6 * 3];
        let mask = vec![255u8; 8 * 6];
        for (i, split) in [Split::Train, Split::Val, Split::Test]
            .into_iter()
            .enumerate()
        {
            let row = ManifestRow {
                id: format!("pair-{i}"),
                split,
                force_n: hnet_units::TipForce::new(0.1, 0.0, -0.2),
                extra: vec![("source".into(), "test".into())],
            };
            let rgb = ImageRef {
                width: 8,
                height: 6,
                channels: 3,
                pixels: &pixels,
            };
            let grey = ImageRef {
                width: 8,
                height: 6,
                channels: 1,
                pixels: &mask,
            };
            archive
                .add_pair(row, [rgb, rgb, grey, grey], &serde_json::json!({}))
                .unwrap();
        }
        let bytes = archive
            .finish(&DatasetHeader::new(
                hnet_units::ImageSize::new(8, 6),
                3,
                serde_json::json!({"generator": "test"}),
            ))
            .unwrap();

        let dir = std::env::temp_dir().join(format!("hnet-archive-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        zip::ZipArchive::new(Cursor::new(bytes))
            .unwrap()
            .extract(&dir)
            .unwrap();
        let dataset = Dataset::open(&dir.join("labels")).unwrap();
        assert_eq!(dataset.rows.len(), 3);
        let pair = dataset.load_pair(&dataset.rows[0], None).unwrap();
        assert_eq!(pair.size, hnet_units::ImageSize::new(8, 6));
        assert!(pair.mask_a.iter().all(|&m| m == 1.0));
        std::fs::remove_dir_all(dir).ok();
    }
}
