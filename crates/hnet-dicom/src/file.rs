//! One DICOM Part 10 file, from its bytes (the page passes bytes; natively [`crate::open`] reads
//! them from disk): its frames, the header's window, its geometry and its timing. The reader
//! keeps no patient identifier (see [`crate::deidentify`]).

use dicom_dictionary_std::tags;
use dicom_encoding::transfer_syntax::TransferSyntaxIndex;
use dicom_object::{OpenFileOptions, ReadError, file::ReadPreamble};
use dicom_pixeldata::PixelDecoder;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use hnet_units::ImageSize;

use crate::attributes::{DicomObject, number, numbers, required_count, text};
use crate::error::{Cause, DicomError};
use crate::frames::{Frames, ModalityLut, Monochrome, PixelCoding};
use crate::geometry::HeaderGeometry;
use crate::timing::FrameTiming;
use crate::window::WindowLevel;

/// Where the `DICM` marker of a Part 10 file starts: after the 128-byte preamble.
const PREAMBLE_BYTES: usize = 128;

/// What one file holds, without its patient identifiers.
#[derive(Debug, Clone, PartialEq)]
pub struct CineFile {
    /// The file's name (as given by the caller: a file name, never its content).
    pub name: String,
    /// Its frames.
    pub frames: Frames,
    /// The header's first Window Center/Width, when present.
    pub window: Option<WindowLevel>,
    /// Its geometry attributes.
    pub geometry: HeaderGeometry,
    /// When its frames were taken.
    pub timing: FrameTiming,
    /// Instance Number, which orders the files of a series.
    pub instance_number: Option<i64>,
}

/// Whether `error` or one of its causes is an I/O error at the end of the input.
fn ends_early(error: &(dyn std::error::Error + 'static)) -> bool {
    let mut next = Some(error);
    while let Some(e) = next {
        if e.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::UnexpectedEof)
        {
            return true;
        }
        next = e.source();
    }
    false
}

/// Parses the Part 10 bytes of `file` (with or without the 128-byte preamble) into dicom-rs's
/// object. Errors say whether the bytes are not DICOM, truncated or in an unknown encoding.
pub fn parse(file: &str, bytes: &[u8]) -> Result<DicomObject, DicomError> {
    let body = if bytes.get(PREAMBLE_BYTES..PREAMBLE_BYTES + 4) == Some(b"DICM") {
        &bytes[PREAMBLE_BYTES..]
    } else if bytes.starts_with(b"DICM") {
        bytes
    } else {
        return Err(DicomError::NotDicom {
            file: file.into(),
            reason: format!(
                "no `DICM` marker after a {PREAMBLE_BYTES}-byte preamble ({} bytes in all)",
                bytes.len()
            ),
            cause: None,
        });
    };
    OpenFileOptions::new()
        .read_preamble(ReadPreamble::Never)
        .from_reader(body)
        .map_err(|error| match error {
            ReadError::ReadUnrecognizedTransferSyntax { uid, .. } => {
                DicomError::UnsupportedTransferSyntax {
                    file: file.into(),
                    uid,
                    name: "unknown".into(),
                }
            }
            ReadError::ReadUnsupportedTransferSyntax { uid, name, .. }
            | ReadError::ReadUnsupportedTransferSyntaxWithSuggestion { uid, name, .. } => {
                DicomError::UnsupportedTransferSyntax {
                    file: file.into(),
                    uid: uid.into(),
                    name: name.into(),
                }
            }
            error if ends_early(&error) => DicomError::Truncated {
                file: file.into(),
                reason: "it ends inside a data element".into(),
                cause: Some(Box::new(error)),
            },
            error @ ReadError::ParseMetaDataSet { .. } => DicomError::NotDicom {
                file: file.into(),
                reason: "unreadable file meta information".into(),
                cause: Some(Box::new(error)),
            },
            error => DicomError::NotDicom {
                file: file.into(),
                reason: "unreadable data set".into(),
                cause: Some(Box::new(error)),
            },
        })
}

/// Reads one file's frames, window, geometry and timing from its Part 10 bytes; `file` names it
/// in errors.
pub fn read_cine_file(file: &str, bytes: &[u8]) -> Result<CineFile, DicomError> {
    let object = parse(file, bytes)?;
    check_transfer_syntax(&object, file)?;
    let frames = read_frames(&object, file)?;
    let window = match (
        numbers(&object, file, tags::WINDOW_CENTER, "WindowCenter")?,
        numbers(&object, file, tags::WINDOW_WIDTH, "WindowWidth")?,
    ) {
        (Some(centres), Some(widths)) => Some(WindowLevel::new(centres[0], widths[0])),
        _ => None,
    };
    let geometry = HeaderGeometry::read(&object, file, frames.size)?;
    let timing = FrameTiming::read(&object, file, frames.count())?;
    let instance_number = number(&object, file, tags::INSTANCE_NUMBER, "InstanceNumber")?
        .filter(|n| n.fract() == 0.0)
        .map(|n| n as i64);
    Ok(CineFile {
        name: file.into(),
        frames,
        window,
        geometry,
        timing,
        instance_number,
    })
}

/// Refuses transfer syntaxes whose pixel data this build cannot decode (JPEG 2000, JPEG-LS, ...).
fn check_transfer_syntax(object: &DicomObject, file: &str) -> Result<(), DicomError> {
    let uid = object.meta().transfer_syntax();
    match TransferSyntaxRegistry.get(uid) {
        Some(ts) if ts.can_decode_all() => Ok(()),
        found => Err(DicomError::UnsupportedTransferSyntax {
            file: file.into(),
            uid: uid.into(),
            name: found.map_or("unknown", |ts| ts.name()).into(),
        }),
    }
}

/// The frames of `object`: monochrome, 8 to 16 bits allocated, decoded to codes.
fn read_frames(object: &DicomObject, file: &str) -> Result<Frames, DicomError> {
    let count = |tag, name| required_count(object, file, tag, name);
    let samples = count(tags::SAMPLES_PER_PIXEL, "SamplesPerPixel")?;
    let photometric = text(object, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_default();
    let monochrome = match photometric.as_str() {
        "MONOCHROME1" if samples == 1 => Monochrome::One,
        "MONOCHROME2" if samples == 1 => Monochrome::Two,
        _ => {
            return Err(DicomError::Colour {
                file: file.into(),
                photometric: if photometric.is_empty() {
                    "no PhotometricInterpretation".into()
                } else {
                    photometric
                },
                samples: samples.min(u32::from(u16::MAX)) as u16,
            });
        }
    };
    let bits_allocated = count(tags::BITS_ALLOCATED, "BitsAllocated")?;
    let bits_stored =
        number(object, file, tags::BITS_STORED, "BitsStored")?.map_or(bits_allocated, |b| b as u32);
    if !matches!(bits_allocated, 8 | 16) || bits_stored == 0 || bits_stored > bits_allocated {
        return Err(DicomError::BitDepth {
            file: file.into(),
            bits_allocated: bits_allocated.min(u32::from(u16::MAX)) as u16,
            bits_stored: bits_stored.min(u32::from(u16::MAX)) as u16,
        });
    }
    let size = ImageSize::new(
        count(tags::COLUMNS, "Columns")? as usize,
        count(tags::ROWS, "Rows")? as usize,
    );
    let frame_count = number(object, file, tags::NUMBER_OF_FRAMES, "NumberOfFrames")?
        .map_or(1, |n| n.max(1.0) as usize);
    let signed = number(
        object,
        file,
        tags::PIXEL_REPRESENTATION,
        "PixelRepresentation",
    )?
    .is_some_and(|r| r == 1.0);
    if object
        .element_opt(tags::PIXEL_DATA)
        .ok()
        .flatten()
        .is_none()
    {
        return Err(DicomError::Truncated {
            file: file.into(),
            reason: "it has no Pixel Data".into(),
            cause: None,
        });
    }
    let decoded = object.decode_pixel_data().map_err(|e| DicomError::Decode {
        file: file.into(),
        cause: Box::new(e) as Cause,
    })?;
    let bytes_per_sample = if bits_allocated == 8 { 1 } else { 2 };
    let needed = size.pixels() * frame_count * bytes_per_sample;
    let data = decoded.data();
    if data.len() < needed {
        return Err(DicomError::Truncated {
            file: file.into(),
            reason: format!(
                "its pixel data holds {} bytes; {frame_count} frames of {size} pixels at \
                 {bits_allocated} bits need {needed}",
                data.len()
            ),
            cause: None,
        });
    }
    let coding = PixelCoding {
        bits_stored: bits_stored as u16,
        signed,
    };
    let codes = if bytes_per_sample == 1 {
        data[..needed]
            .iter()
            .map(|&b| coding.code_of_raw(u16::from(b)))
            .collect()
    } else {
        data[..needed]
            .chunks_exact(2)
            .map(|b| coding.code_of_raw(u16::from_le_bytes([b[0], b[1]])))
            .collect()
    };
    let modality = ModalityLut {
        slope: number(object, file, tags::RESCALE_SLOPE, "RescaleSlope")?
            .filter(|s| s.is_finite() && *s != 0.0)
            .unwrap_or(1.0),
        intercept: number(object, file, tags::RESCALE_INTERCEPT, "RescaleIntercept")?
            .filter(|i| i.is_finite())
            .unwrap_or(0.0),
    };
    Ok(Frames {
        size,
        coding,
        modality,
        monochrome,
        codes,
    })
}
