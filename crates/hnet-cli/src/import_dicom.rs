//! `hnet import --dicom-a A --dicom-b B --forces forces.csv`: a biplane DICOM cine into the
//! dataset format, one pair per frame that the forces CSV labels, each pair's record holding both
//! planes' C-arm geometry. Nothing that could identify the patient is written: no header value
//! besides the geometry and frame times, and no path (folder names often carry a patient's name).
//!
//! The dataset format needs a force for every pair, so the forces CSV is required; frames it
//! does not list are left out and counted.

use std::collections::HashSet;

use anyhow::{Context, bail};
use hnet_dicom::PlaneGeometry;
use hnet_twin::dataset::force_table::{ForceRow, read_force_table};
use hnet_twin::dataset::import::{recording_mask, row_origin};
use hnet_twin::dataset::{
    DatasetError, DatasetHeader, DatasetWriter, ImageRef, ManifestRow, assign_splits, resized,
    sample_files,
};
use hnet_units::ImageSize;
use serde_json::json;

use crate::cine::{grey_pair, open_cine};
use crate::import::ImportArgs;
use crate::progress;

/// The forces CSV's key column for DICOM: the frame number, from 1.
const FRAME_COLUMN: &str = "frame";

/// The id of frame `number` (from 1).
fn frame_id(number: usize) -> String {
    format!("frame{number:05}")
}

/// The forces CSV's rows with the 0-based frame each labels; bad rows as errors.
fn labelled_frames(
    args: &ImportArgs,
    frames: usize,
) -> anyhow::Result<Vec<Result<(usize, ForceRow), DatasetError>>> {
    let path = &args.forces;
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let rows = read_force_table(&bytes, &[FRAME_COLUMN])
        .map_err(|e| DatasetError::caused_by(path, "is not a forces table", e))?;
    let mut seen = HashSet::new();
    Ok(rows
        .into_iter()
        .map(|row| {
            let row = row.map_err(|e| DatasetError::caused_by(path, "has a bad row", e))?;
            let frame = row
                .key
                .parse::<usize>()
                .ok()
                .filter(|n| (1..=frames).contains(n))
                .ok_or_else(|| {
                    DatasetError::new(
                        path,
                        format!(
                            "line {}: frame `{}` is not a frame number from 1 to {frames}",
                            row.line, row.key
                        ),
                    )
                })?;
            if !seen.insert(frame) {
                return Err(DatasetError::new(
                    path,
                    format!("line {}: frame {frame} appears twice", row.line),
                ));
            }
            Ok((frame - 1, row))
        })
        .collect())
}

/// A plane's geometry as recorded with each pair: the C-arm at the dataset's size, its camera
/// matrix, and the attributes that came from the default.
fn view_record(geometry: &PlaneGeometry, size: ImageSize) -> serde_json::Value {
    let carm = geometry.carm.with_image_size(size);
    json!({
        "carm": carm,
        "camera_matrix": carm.camera_matrix(),
        "missing_geometry": geometry.missing.iter().map(|t| t.keyword()).collect::<Vec<_>>(),
    })
}

pub fn run(args: &ImportArgs) -> anyhow::Result<()> {
    let (Some(plane_a), Some(plane_b)) = (&args.dicom_a, &args.dicom_b) else {
        bail!("give --view-a and --view-b (image folders) or --dicom-a and --dicom-b (DICOM)");
    };
    let cine = open_cine(plane_a, plane_b)?;
    let frames = cine.pairing.pairs.len();
    let [a, b] = &cine.planes;
    let size = match args.checked_size()? {
        Some(side) => ImageSize::square(side),
        None if a.frames.size == b.frames.size => a.frames.size,
        None => bail!(
            "plane A ({}) is {} but plane B ({}) is {}: give --size to resize both",
            a.source,
            a.frames.size,
            b.source,
            b.frames.size
        ),
    };
    let mut skipped = Vec::new();
    let mut labelled = Vec::new();
    for row in labelled_frames(args, frames)? {
        match row {
            Ok(row) => labelled.push(row),
            Err(e) if args.skip_bad => skipped.push(e),
            Err(e) => return Err(e.into()),
        }
    }
    if labelled.is_empty() {
        bail!(
            "{}: no usable rows (a `{FRAME_COLUMN}` column of frame numbers from 1 to {frames}, \
             and fx, fy, fz in newtons): nothing to import",
            args.forces.display()
        );
    }
    labelled.sort_by_key(|(frame, _)| *frame);
    let header = DatasetHeader::new(
        size,
        labelled.len(),
        json!({
            "generator": "hnet import (DICOM)",
            "frames": frames,
            "paired_by_time": cine.pairing.timed,
            "views": [view_record(&a.geometry, size), view_record(&b.geometry, size)],
            "threshold": args.threshold.record(),
            "bright_catheter": args.bright_catheter,
            "seed": args.seed,
        }),
    );
    let writer = DatasetWriter::create_or_resume(&args.out, &header)?;
    let splits = assign_splits(labelled.len(), args.seed);
    let bar = progress::bar(labelled.len() as u64, "importing");
    for ((frame, row), split) in labelled.iter().zip(splits) {
        let id = frame_id(frame + 1);
        if writer.has_sample(&id) {
            bar.inc(1);
            continue;
        }
        let pair = cine.pairing.pairs[*frame];
        let [view_a, view_b] = grey_pair(&cine, pair.frame).map(|image| {
            resized(image::DynamicImage::ImageLuma8(image), size)
                .to_luma8()
                .into_raw()
        });
        let [mask_a, mask_b] = [&view_a, &view_b]
            .map(|grey| recording_mask(grey.clone(), args.threshold, args.bright_catheter));
        let time = pair.time_s.map(|t| t.to_string()).unwrap_or_default();
        let manifest = ManifestRow {
            id: id.clone(),
            split,
            force_n: row.force_n,
            extra: [
                ("frame".into(), (frame + 1).to_string()),
                ("time_s".into(), time),
            ]
            .into_iter()
            .chain(row_origin(row, &args.label_origin).columns())
            .collect(),
        };
        let record = json!({
            "frame": frame + 1,
            "time_s": pair.time_s,
            "csv_line": row.line,
            "views": [view_record(&a.geometry, size), view_record(&b.geometry, size)],
        });
        fn image(size: ImageSize, pixels: &[u8]) -> ImageRef<'_> {
            ImageRef {
                width: size.width,
                height: size.height,
                channels: 1,
                pixels,
            }
        }
        let files = sample_files(
            &manifest,
            [
                image(size, &view_a),
                image(size, &view_b),
                image(size, &mask_a),
                image(size, &mask_b),
            ],
            &record,
        );
        writer.write_sample(&id, &files)?;
        bar.inc(1);
    }
    writer.finish()?;
    bar.finish_and_clear();
    let skipped_rows = skipped.len();
    for problem in skipped {
        // anyhow's alternate form prints the problem with its causes, as `main` does.
        eprintln!("skipped: {:#}", anyhow::Error::from(problem));
    }
    eprintln!(
        "{} frame pairs of {frames} imported into {}{}",
        labelled.len(),
        args.out.display(),
        if skipped_rows == 0 {
            String::new()
        } else {
            format!(", {skipped_rows} rows skipped")
        }
    );
    Ok(())
}
