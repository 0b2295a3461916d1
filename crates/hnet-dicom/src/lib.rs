//! DICOM input for H-Net Studio: biplane X-ray angiography (XA) and radiofluoroscopy (RF) cines,
//! the one reader behind `hnet import --dicom-a/--dicom-b`, `hnet trace` and the page's cine.
//!
//! - [`read_cine_file`]: a Part 10 file from its bytes (single- or multi-frame, MONOCHROME1 or
//!   MONOCHROME2, 8-16 bits allocated, signed or unsigned) into [`Frames`], with the header's
//!   window, geometry and frame timing; natively [`open_series`] reads a file or a folder.
//! - [`Frames`] and [`WindowLevel`]: the modality LUT (Rescale Slope/Intercept) and the VOI LUT
//!   (the first Window Center/Width, else the frame's range) to 8-bit grey, as pure functions.
//! - [`HeaderGeometry`]: Positioner angles, source distances and Imager Pixel Spacing as the
//!   twin's [`hnet_twin::simulator::carm::CArm`], listing the attributes that were missing
//!   ([`GeometryTag`]) and filled from the plane's default.
//! - [`pair_frames`]: plane A's frames with plane B's, checked against their frame times;
//!   [`BiplaneCine`]: both planes and their pairs, with what the user must be told.
//! - [`trace_csv`]: a force trace over a cine, the CSV of `hnet trace` and the page.
//! - [`deidentify`]: patient identifiers; the reader keeps none of them.
//! - [`write_xa`], [`twin_cine`] and [`twin_push_cine`]: XA multi-frame files from the twin's
//!   frames (the tests' input, the page's sample cine).
//!
//! Pixel data: uncompressed (implicit or explicit VR little endian, and explicit big endian),
//! and the encapsulated syntaxes dicom-pixeldata decodes in pure Rust with its `jpeg` and `rle`
//! features: JPEG baseline (8-bit), extended (12-bit) and lossless, and RLE lossless. JPEG 2000,
//! JPEG-LS and JPEG XL are refused with the transfer syntax named ([`DicomError`]). Everything
//! here compiles for `wasm32-unknown-unknown` except [`open`] (files on disk).

mod attributes;
mod cine;
pub mod deidentify;
mod error;
mod file;
mod frames;
mod geometry;
#[cfg(not(target_arch = "wasm32"))]
pub mod open;
mod pairing;
mod series;
mod timing;
mod trace;
mod twin_cine;
mod window;
pub mod writer;

pub use attributes::DicomObject;
pub use cine::{BiplaneCine, missing_geometry_note};
pub use deidentify::{PATIENT_IDENTIFIERS, deidentify, identifiers_present};
pub use error::{Cause, DicomError};
pub use file::{CineFile, parse, read_cine_file};
pub use frames::{Frames, ModalityLut, Monochrome, PixelCoding};
pub use geometry::{GeometryTag, HeaderGeometry, Plane, PlaneGeometry};
#[cfg(not(target_arch = "wasm32"))]
pub use open::{open_cine_file, open_series};
pub use pairing::{FramePair, Pairing, PairingError, PairingWarning, pair_frames};
pub use series::PlaneSeries;
pub use timing::{FrameTiming, parse_date_time};
pub use trace::{TRACE_COLUMNS, TracePoint, trace_csv};
pub use twin_cine::{FRAME_TIME_MS, TwinCine, cine_views, twin_cine, twin_push_cine};
pub use window::WindowLevel;
pub use writer::{PatientIdentity, XaCine, write_xa, xa_object};
