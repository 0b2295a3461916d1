//! `hnet import`: real recordings into the dataset format: two folders of images, or two DICOM
//! series (plane A and plane B of a biplane cine, `import_dicom`).

use std::path::PathBuf;

use anyhow::bail;
use hnet_twin::dataset::import::{ImportOptions, MaskThreshold, import_recordings};
use hnet_twin::dataset::label_origin::LabelOrigin;

use crate::progress;

#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["view_a", "dicom_a"])))]
pub struct ImportArgs {
    /// Folder of view A images.
    #[arg(long, requires = "view_b")]
    view_a: Option<PathBuf>,
    /// Folder of view B images (same file names as view A).
    #[arg(long, requires = "view_a", conflicts_with_all = ["dicom_a", "dicom_b"])]
    view_b: Option<PathBuf>,
    /// Plane A of a biplane DICOM (XA/RF) cine: a file, or a folder of its files.
    #[arg(long, requires = "dicom_b", conflicts_with = "view_a")]
    pub(crate) dicom_a: Option<PathBuf>,
    /// Plane B of the cine, frame for frame with plane A.
    #[arg(long, requires = "dicom_a")]
    pub(crate) dicom_b: Option<PathBuf>,
    /// CSV with a header: a key column and `fx,fy,fz` in newtons. For image folders the key is
    /// the image (`image`, `file`, `frame` or `name`); for DICOM it is `frame`, the frame
    /// number from 1 (frames without a row are not imported: the dataset format needs a force
    /// for every pair).
    #[arg(long)]
    pub(crate) forces: PathBuf,
    /// Output dataset folder.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Mask threshold: a grey level 0-255 (the catheter is at or below it) or `otsu`.
    #[arg(long, default_value = "otsu", value_parser = parse_threshold)]
    pub(crate) threshold: MaskThreshold,
    /// The catheter is brighter than its background (masks take the pixels above the level).
    #[arg(long)]
    pub(crate) bright_catheter: bool,
    /// Resize every image to SIZE x SIZE pixels (otherwise all must have the same size).
    #[arg(long)]
    pub(crate) size: Option<usize>,
    /// Report bad rows and images and go on instead of stopping at the first one.
    #[arg(long)]
    pub(crate) skip_bad: bool,
    /// Seed of the 80/10/10 train/val/test split.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Where the forces came from, for rows whose table has no `label_origin` column:
    /// `measured` (a force sensor's log), `typed` or `imported` (not known). Written to the
    /// manifest; `hnet train --labels` and `hnet calibrate` read it.
    #[arg(long, default_value = "imported", value_parser = parse_origin)]
    pub(crate) label_origin: LabelOrigin,
}

fn parse_origin(text: &str) -> Result<LabelOrigin, String> {
    match text {
        "measured" => Ok(LabelOrigin::Measured),
        "typed" => Ok(LabelOrigin::Typed),
        "imported" => Ok(LabelOrigin::Imported),
        _ => Err(format!(
            "`{text}` is not measured, typed or imported (a model's estimate is not imported as a label)"
        )),
    }
}

fn parse_threshold(text: &str) -> Result<MaskThreshold, String> {
    if text == "otsu" {
        return Ok(MaskThreshold::Otsu);
    }
    text.parse::<u8>()
        .map(MaskThreshold::Level)
        .map_err(|_| format!("`{text}` is neither a grey level 0-255 nor `otsu`"))
}

impl ImportArgs {
    /// Whether the pairs come from the two planes of a DICOM cine (`import_dicom`), not from
    /// image folders.
    pub fn is_dicom(&self) -> bool {
        self.dicom_a.is_some()
    }

    /// The `--size` asked for (pixels, square), refused when 0.
    pub fn checked_size(&self) -> anyhow::Result<Option<usize>> {
        if self.size == Some(0) {
            bail!("--size must be at least 1");
        }
        Ok(self.size)
    }
}

pub fn run(args: &ImportArgs) -> anyhow::Result<()> {
    let size = args.checked_size()?;
    let (Some(view_a), Some(view_b)) = (&args.view_a, &args.view_b) else {
        bail!("give --view-a and --view-b (image folders), or --dicom-a and --dicom-b");
    };
    let options = ImportOptions {
        view_a: view_a.clone(),
        view_b: view_b.clone(),
        forces: args.forces.clone(),
        out: args.out.clone(),
        threshold: args.threshold,
        bright_catheter: args.bright_catheter,
        size,
        skip_bad: args.skip_bad,
        seed: args.seed,
        label_origin: args.label_origin.clone(),
    };
    let bar = progress::bar(0, "importing");
    let report = import_recordings(&options, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let skipped = report.skipped.len();
    for problem in report.skipped {
        // anyhow's alternate form prints the problem with its causes, as `main` does.
        eprintln!("skipped: {:#}", anyhow::Error::from(problem));
    }
    eprintln!(
        "{} stereo pairs imported into {}{}",
        report.imported,
        args.out.display(),
        if skipped == 0 {
            String::new()
        } else {
            format!(", {skipped} rows skipped")
        }
    );
    Ok(())
}
