//! One plane's cine: the frames of one multi-frame file, or of several files (a folder) in
//! Instance Number order, with the plane's geometry, window and frame times.

use crate::error::DicomError;
use crate::file::CineFile;
use crate::frames::Frames;
use crate::geometry::{Plane, PlaneGeometry};
use crate::window::WindowLevel;

/// A plane's frames and what the headers say about them.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneSeries {
    /// Which plane.
    pub plane: Plane,
    /// The file or folder the series came from, as the caller named it.
    pub source: String,
    /// Its files' names, in frame order.
    pub files: Vec<String>,
    /// Every frame, in order.
    pub frames: Frames,
    /// The first file's Window Center/Width, when present.
    pub window: Option<WindowLevel>,
    /// The plane's C-arm (from the first file) and the attributes it lacked.
    pub geometry: PlaneGeometry,
    /// Each frame's time after the first frame, seconds, when the headers give it.
    pub frame_times_s: Option<Vec<f64>>,
    /// The first file's Acquisition DateTime, seconds since 1970, when present.
    pub start_s: Option<f64>,
}

impl PlaneSeries {
    /// Joins the files of one plane (`source` names the file or folder). Files are ordered by
    /// Instance Number when all have one, else kept in the given order; all must share the
    /// image size and pixel coding.
    pub fn from_files(
        plane: Plane,
        source: &str,
        mut files: Vec<CineFile>,
    ) -> Result<Self, DicomError> {
        if files.is_empty() {
            return Err(DicomError::EmptyFolder {
                file: source.into(),
            });
        }
        if files.iter().all(|f| f.instance_number.is_some()) {
            files.sort_by_key(|f| f.instance_number);
        }
        let first = &files[0];
        for other in &files[1..] {
            let (a, b) = (&first.frames, &other.frames);
            let differs = if a.size != b.size {
                Some(("is", b.size.to_string(), a.size.to_string()))
            } else if (a.coding, a.monochrome) != (b.coding, b.monochrome) {
                Some((
                    "is coded",
                    format!("{:?} {:?}", b.coding, b.monochrome),
                    format!("{:?} {:?}", a.coding, a.monochrome),
                ))
            } else {
                None
            };
            if let Some((verb, found, expected)) = differs {
                return Err(DicomError::Inconsistent {
                    file: other.name.clone(),
                    problem: format!("{verb} {found}"),
                    first: first.name.clone(),
                    first_value: expected,
                });
            }
        }
        let frame_times_s = series_times(&files);
        let first = &files[0];
        let (window, geometry, start_s) = (
            first.window,
            first.geometry.carm(plane),
            first.timing.start_s,
        );
        let names = files.iter().map(|f| f.name.clone()).collect();
        let frames = Frames::concatenated(files.into_iter().map(|f| f.frames).collect())
            .expect("checked above: one size and coding");
        Ok(Self {
            plane,
            source: source.into(),
            files: names,
            frames,
            window,
            geometry,
            frame_times_s,
            start_s,
        })
    }

    /// Number of frames.
    pub fn count(&self) -> usize {
        self.frames.count()
    }

    /// The window a frame is first shown with: the header's, or the frame's own range.
    pub fn initial_window(&self, frame: usize) -> WindowLevel {
        self.window.unwrap_or_else(|| {
            let (min, max) = self.frames.range(frame).unwrap_or((0.0, 255.0));
            WindowLevel::spanning(min, max)
        })
    }

    /// Frame `frame` (0-based) as 8-bit grey under `window`, row-major.
    pub fn grey_frame(&self, frame: usize, window: WindowLevel) -> Option<Vec<u8>> {
        self.frames.grey_frame(frame, window)
    }
}

/// The frames' times over several files: one file's own frame times, or, when every file has
/// an Acquisition DateTime, each file's start plus its frames' times (single frames at 0).
fn series_times(files: &[CineFile]) -> Option<Vec<f64>> {
    if let [only] = files {
        return only.timing.frame_times_s.clone();
    }
    let origin = files[0].timing.start_s?;
    let mut times = Vec::new();
    for file in files {
        let start = file.timing.start_s? - origin;
        match (&file.timing.frame_times_s, file.frames.count()) {
            (Some(own), _) => times.extend(own.iter().map(|t| start + t)),
            (None, 1) => times.push(start),
            (None, _) => return None,
        }
    }
    Some(times)
}
