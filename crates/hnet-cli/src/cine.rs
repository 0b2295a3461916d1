//! A biplane DICOM cine on the command line: both planes read, paired frame by frame, and the
//! user told what the headers lacked and how the frames were paired (`hnet import --dicom-a`,
//! `hnet trace`).

use std::path::Path;

use hnet_dicom::{Pairing, Plane, PlaneSeries, open_series, pair_frames};

/// Plane A and plane B and their frame pairs.
pub struct BiplaneCine {
    /// Plane A and plane B.
    pub planes: [PlaneSeries; 2],
    /// One pair per frame.
    pub pairing: Pairing,
}

impl BiplaneCine {
    /// Reads both planes (a file or a folder each) and pairs them; prints to standard error the
    /// geometry attributes that were missing (and the default used) and any pairing warning.
    pub fn open(plane_a: &Path, plane_b: &Path) -> anyhow::Result<Self> {
        let planes = [
            open_series(Plane::A, plane_a)?,
            open_series(Plane::B, plane_b)?,
        ];
        for series in &planes {
            let missing = &series.geometry.missing;
            if !missing.is_empty() {
                let names: Vec<&str> = missing.iter().map(|tag| tag.keyword()).collect();
                eprintln!(
                    "warning: plane {} ({}) lacks {}: the default {} geometry is used for them",
                    series.plane.name(),
                    series.source,
                    names.join(", "),
                    match series.plane {
                        Plane::A => "frontal",
                        Plane::B => "lateral",
                    },
                );
            }
        }
        let pairing = pair_frames(&planes[0], &planes[1])?;
        for warning in &pairing.warnings {
            eprintln!("warning: {warning}");
        }
        Ok(Self { planes, pairing })
    }

    /// Frame `frame` (0-based) of both planes as 8-bit grey images, each under its header's
    /// window (or the frame's own range).
    pub fn grey_pair(&self, frame: usize) -> [image::GrayImage; 2] {
        self.planes.each_ref().map(|series| {
            let grey = series
                .grey_frame(frame, series.initial_window(frame))
                .expect("a paired frame exists in both planes");
            let size = series.frames.size;
            image::GrayImage::from_raw(size.width as u32, size.height as u32, grey)
                .expect("a frame has its series' size")
        })
    }
}
