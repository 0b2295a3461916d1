//! `hnet contact-sheet`: a picture of a dataset's first pairs (both views and both masks).

use std::path::PathBuf;

use anyhow::{Context, bail};
use hnet_twin::dataset::Dataset;
use hnet_units::ImageSize;
use image::{Rgb, RgbImage, imageops};

#[derive(clap::Args, Debug)]
pub struct ContactSheetArgs {
    /// Dataset folder.
    #[arg(long)]
    data: PathBuf,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Number of pairs (rows).
    #[arg(long, default_value_t = 3)]
    count: usize,
    /// Side of each tile in pixels.
    #[arg(long, default_value_t = 160)]
    tile: u32,
}

pub fn run(args: &ContactSheetArgs) -> anyhow::Result<()> {
    let dataset = Dataset::open(&args.data)?;
    let rows: Vec<_> = dataset.rows.iter().take(args.count).collect();
    if rows.is_empty() {
        bail!("{} holds no pairs", args.data.display());
    }
    let (tile, gap) = (args.tile, 4u32);
    let width = 4 * tile + 5 * gap;
    let height = rows.len() as u32 * (tile + gap) + gap;
    let mut sheet = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    for (r, row) in rows.iter().enumerate() {
        let pair = dataset.load_pair(row, Some(ImageSize::square(tile as usize)))?;
        let grey = |mask: &[f32]| -> Vec<u8> {
            mask.iter()
                .flat_map(|&m| {
                    let v = (m * 255.0).round() as u8;
                    [v, v, v]
                })
                .collect()
        };
        let tiles = [
            pair.view_a.clone(),
            pair.view_b.clone(),
            grey(&pair.mask_a),
            grey(&pair.mask_b),
        ];
        for (c, pixels) in tiles.into_iter().enumerate() {
            let image = RgbImage::from_raw(tile, tile, pixels).context("tile size")?;
            imageops::overlay(
                &mut sheet,
                &image,
                i64::from(gap + c as u32 * (tile + gap)),
                i64::from(gap + r as u32 * (tile + gap)),
            );
        }
    }
    sheet
        .save(&args.out)
        .with_context(|| format!("cannot write '{}'", args.out.display()))?;
    eprintln!(
        "{}: {} pairs (view A, view B, mask A, mask B)",
        args.out.display(),
        rows.len()
    );
    Ok(())
}
