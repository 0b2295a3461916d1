//! A biplane DICOM cine on the command line: both planes read from disk and paired frame by
//! frame ([`hnet_dicom::BiplaneCine`]), the user told on standard error what the headers lacked
//! and how the frames were paired (`hnet import --dicom-a`, `hnet trace`).

use std::path::Path;

use hnet_dicom::{BiplaneCine, Plane, open_series};

/// Reads both planes (a file or a folder each) and pairs them; prints each note (missing
/// geometry attributes and the default used, pairing warnings) as a warning.
pub fn open_cine(plane_a: &Path, plane_b: &Path) -> anyhow::Result<BiplaneCine> {
    let cine = BiplaneCine::pair(
        open_series(Plane::A, plane_a)?,
        open_series(Plane::B, plane_b)?,
    )?;
    for note in cine.notes() {
        eprintln!("warning: {note}");
    }
    Ok(cine)
}

/// Frame `frame` (0-based) of both planes as 8-bit grey images, each under its header's window
/// (or the frame's own range).
pub fn grey_pair(cine: &BiplaneCine, frame: usize) -> [image::GrayImage; 2] {
    Plane::BOTH.map(|plane| {
        let series = cine.series(plane);
        let grey = cine
            .grey_frame(plane, frame, series.initial_window(frame))
            .expect("a paired frame exists in both planes");
        let size = series.frames.size;
        image::GrayImage::from_raw(size.width as u32, size.height as u32, grey)
            .expect("a frame has its series' size")
    })
}
