//! One DICOM Part 10 file, from its bytes (the page passes bytes; natively [`crate::open`] reads
//! them from disk): its frames, the header's window, its geometry and its timing. The reader
//! keeps no patient identifier (see [`crate::deidentify`]).

use dicom_dictionary_std::{tags, uids};
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
    check_element_lengths(file, body)?;
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

/// The transfer syntaxes whose data sets are not explicit VR little endian.
const IMPLICIT_VR_LITTLE_ENDIAN: &str = "1.2.840.10008.1.2";
const EXPLICIT_VR_BIG_ENDIAN: &str = "1.2.840.10008.1.2.2";
const DEFLATED: &str = "1.2.840.10008.1.2.1.99";

/// Explicit VRs with a 2-byte length (PS3.5 7.1.2). Every other VR, an unknown one too (which
/// dicom-rs reads as UN), has 2 reserved bytes and a 4-byte length.
const SHORT_VRS: [&[u8; 2]; 21] = [
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN",
    b"SH", b"SL", b"SS", b"ST", b"TM", b"UI", b"UL", b"US",
];

/// Walks the element headers of a Part 10 body (from `DICM`) and refuses any element or item
/// whose defined length runs past the end of the bytes, before dicom-rs reads it: its parser
/// reserves an element's claimed length up front, so a 2 KB file claiming 4 GiB of pixel data
/// would otherwise ask for 4 GiB. Elements of undefined length are walked into (sequences,
/// encapsulated pixel data); deflated data sets are left to dicom-rs. Headers cut short are left
/// to dicom-rs too, which reports them as truncated.
fn check_element_lengths(file: &str, body: &[u8]) -> Result<(), DicomError> {
    let mut at = 4; // after `DICM`
    let mut explicit = true;
    let mut big_endian = false;
    let mut in_meta = true;
    while at + 8 <= body.len() {
        let u16_at = |i: usize, big: bool| {
            let b = [body[i], body[i + 1]];
            if big {
                u16::from_be_bytes(b)
            } else {
                u16::from_le_bytes(b)
            }
        };
        let u32_at = |i: usize, big: bool| {
            let b = [body[i], body[i + 1], body[i + 2], body[i + 3]];
            if big {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            }
        };
        // The file meta group is always explicit VR little endian.
        let group_le = u16_at(at, false);
        if in_meta && group_le != 0x0002 {
            in_meta = false;
        }
        let big = big_endian && !in_meta;
        let (group, element) = (u16_at(at, big), u16_at(at + 2, big));
        // The explicit VR, when the element has one.
        let mut explicit_vr = None;
        let (length, header) = if group == 0xFFFE {
            // Items and delimiters: no VR, a 4-byte length.
            (u32_at(at + 4, big), 8)
        } else if explicit || in_meta {
            let vr = [body[at + 4], body[at + 5]];
            explicit_vr = Some(vr);
            if SHORT_VRS.contains(&&vr) {
                (u32::from(u16_at(at + 6, big)), 8)
            } else {
                if at + 12 > body.len() {
                    return Ok(());
                }
                (u32_at(at + 8, big), 12)
            }
        } else {
            (u32_at(at + 4, big), 8)
        };
        at += header;
        // Only a sequence (or UN holding one) and encapsulated Pixel Data may have an undefined
        // length (PS3.5 7.1.2, A.4): dicom-rs reads any other such element in ways that may
        // reserve gigabytes (an encapsulated cine whose Pixel Data tag became (7F00,0010) asked
        // for 2.6 GB).
        if length == u32::MAX
            && let Some(vr) = explicit_vr
            && !matches!(&vr, b"SQ" | b"UN")
            && (group, element) != (0x7FE0, 0x0010)
        {
            return Err(DicomError::Truncated {
                file: file.into(),
                reason: format!(
                    "element ({group:04X},{element:04X}) of VR {} has an undefined length, which \
                     only sequences and encapsulated Pixel Data may have",
                    String::from_utf8_lossy(&vr)
                ),
                cause: None,
            });
        }
        if length == u32::MAX || (group == 0xFFFE && element != 0xE000) {
            // Undefined length (walk into it) or a delimiter.
            continue;
        }
        let length = length as usize;
        if length > body.len() - at {
            return Err(DicomError::Truncated {
                file: file.into(),
                reason: format!(
                    "element ({group:04X},{element:04X}) claims {length} bytes but {} remain",
                    body.len() - at
                ),
                cause: None,
            });
        }
        if in_meta && (group, element) == (0x0002, 0x0010) {
            let uid = String::from_utf8_lossy(&body[at..at + length]);
            match uid.trim_end_matches(['\0', ' ']) {
                IMPLICIT_VR_LITTLE_ENDIAN => explicit = false,
                EXPLICIT_VR_BIG_ENDIAN => big_endian = true,
                DEFLATED => return Ok(()),
                _ => {}
            }
        }
        // An item of defined length is skipped whole; its elements are bounded by it.
        at += length;
    }
    Ok(())
}

/// The width and height a JPEG stream's frame header (SOFn) gives, if it has one.
fn jpeg_frame_size(stream: &[u8]) -> Option<(u16, u16)> {
    if !stream.starts_with(&[0xFF, 0xD8]) {
        return None;
    }
    let mut at = 2;
    while at + 9 < stream.len() {
        if stream[at] != 0xFF {
            return None;
        }
        let marker = stream[at + 1];
        let length = usize::from(u16::from_be_bytes([stream[at + 2], stream[at + 3]]));
        if (0xC0..=0xCF).contains(&marker) && !matches!(marker, 0xC4 | 0xC8 | 0xCC) {
            let height = u16::from_be_bytes([stream[at + 5], stream[at + 6]]);
            let width = u16::from_be_bytes([stream[at + 7], stream[at + 8]]);
            return Some((width, height));
        }
        at += 2 + length;
    }
    None
}

/// The fragments of encapsulated Pixel Data (one per frame for the syntaxes read here), or
/// `None` for native pixel data.
fn pixel_fragments(object: &DicomObject) -> Option<&[Vec<u8>]> {
    object
        .element_opt(tags::PIXEL_DATA)
        .ok()
        .flatten()
        .and_then(|e| e.value().fragments())
}

/// Refuses encapsulated JPEG frames whose own size differs from Rows x Columns before they are
/// decoded: a larger frame overruns dicom-rs's frame buffer (a panic), and a frame claiming
/// 65535 x 65535 pixels makes the decoder allocate them infallibly (an abort).
fn check_jpeg_frames(object: &DicomObject, file: &str, size: ImageSize) -> Result<(), DicomError> {
    let Some(fragments) = pixel_fragments(object) else {
        return Ok(());
    };
    for fragment in fragments {
        if let Some((width, height)) = jpeg_frame_size(fragment)
            && (usize::from(width), usize::from(height)) != (size.width, size.height)
        {
            return Err(DicomError::Attribute {
                file: file.into(),
                attribute: "PixelData",
                problem: format!(
                    "holds a JPEG frame of {width} x {height} pixels; Rows and Columns say {size}"
                ),
                cause: None,
            });
        }
    }
    Ok(())
}

/// Bytes one RLE Lossless segment decodes to, as dicom-rs's PackBits reader decodes it (a
/// literal run cut short gives what is there), or `None` when it ends inside a replicate run
/// (which that reader reports as an error).
fn pack_bits_decoded_len(segment: &[u8]) -> Option<usize> {
    let (mut decoded, mut i) = (0usize, 0usize);
    while i < segment.len() {
        let header = segment[i] as i8;
        i += 1;
        match header {
            -127..=-1 => {
                segment.get(i)?;
                decoded += (1 - isize::from(header)) as usize;
                i += 1;
            }
            0..=127 => {
                let run = header as usize + 1;
                decoded += run.min(segment.len() - i);
                i += run;
            }
            -128 => {}
        }
    }
    Some(decoded)
}

/// Refuses RLE Lossless frames that dicom-rs's RLE adapter would index out of bounds (a panic)
/// before they are decoded: a fragment shorter than the 64-byte RLE header, a header claiming
/// more than the standard's 15 segments (its offsets would be read past the fragment), fewer
/// segments than the pixels need (one per byte of a sample), a segment outside the fragment, or
/// one that decodes to fewer than Rows x Columns bytes.
fn check_rle_frames(
    object: &DicomObject,
    file: &str,
    size: ImageSize,
    bytes_per_sample: usize,
) -> Result<(), DicomError> {
    if object.meta().transfer_syntax().trim_end_matches('\0') != uids::RLE_LOSSLESS {
        return Ok(());
    }
    let Some(fragments) = pixel_fragments(object) else {
        return Ok(());
    };
    let refuse = |problem: String| DicomError::Attribute {
        file: file.into(),
        attribute: "PixelData",
        problem,
        cause: None,
    };
    for (frame, fragment) in fragments.iter().enumerate() {
        if fragment.len() < 64 {
            return Err(refuse(format!(
                "holds an RLE frame ({frame}) of {} bytes, shorter than its 64-byte header",
                fragment.len()
            )));
        }
        let word = |k: usize| u32::from_le_bytes(fragment[4 * k..4 * k + 4].try_into().unwrap());
        let segments = word(0) as usize;
        if !(bytes_per_sample..=15).contains(&segments) {
            return Err(refuse(format!(
                "holds an RLE frame ({frame}) of {segments} segments; {bytes_per_sample} to 15 \
                 are possible"
            )));
        }
        for k in 0..bytes_per_sample {
            let start = word(1 + k) as usize;
            let end = if k + 1 < segments {
                word(2 + k) as usize
            } else {
                fragment.len()
            };
            let decoded = fragment
                .get(start..end)
                .and_then(pack_bits_decoded_len)
                .unwrap_or(0);
            if decoded < size.pixels() {
                return Err(refuse(format!(
                    "holds an RLE frame ({frame}) whose segment {k} decodes to {decoded} bytes; \
                     Rows and Columns ({size}) need {}",
                    size.pixels()
                )));
            }
        }
    }
    Ok(())
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
    if size.pixels() == 0 {
        return Err(DicomError::Attribute {
            file: file.into(),
            attribute: if size.width == 0 { "Columns" } else { "Rows" },
            problem: "is 0: an image has at least one pixel".into(),
            cause: None,
        });
    }
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
    check_jpeg_frames(object, file, size)?;
    let bytes_per_sample = if bits_allocated == 8 { 1 } else { 2 };
    check_rle_frames(object, file, size, bytes_per_sample)?;
    let decoded = object.decode_pixel_data().map_err(|e| DicomError::Decode {
        file: file.into(),
        cause: Box::new(e) as Cause,
    })?;
    let data = decoded.data();
    // Checked: a NumberOfFrames of 1e30 must not wrap around to a small size.
    let needed = size
        .pixels()
        .checked_mul(frame_count)
        .and_then(|n| n.checked_mul(bytes_per_sample))
        .unwrap_or(usize::MAX);
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
