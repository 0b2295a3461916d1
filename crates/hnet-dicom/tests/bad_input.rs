//! Bad DICOM input: each case is an error that names the file and the reason, never a panic.

use dicom_core::value::PixelFragmentSequence;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::{tags, uids};
use hnet_dicom::writer::part10_bytes;
use hnet_dicom::{
    DicomError, PairingError, PatientIdentity, Plane, PlaneSeries, XaCine, pair_frames,
    read_cine_file, twin_cine, write_xa, xa_object,
};

const NAME: &str = "run-07/plane-a.dcm";

fn cine() -> XaCine {
    twin_cine(32, 3, 3).unwrap().planes[0].clone()
}

fn message(error: DicomError) -> String {
    assert_eq!(error.file(), NAME);
    let text = error.to_string();
    assert!(text.starts_with(NAME), "{text}");
    text
}

#[test]
fn bytes_that_are_not_dicom_are_named() {
    for bytes in [&b"\x89PNG\r\n\x1a\n"[..], &[0u8; 300][..], b""] {
        let error = read_cine_file(NAME, bytes).unwrap_err();
        assert!(matches!(error, DicomError::NotDicom { .. }), "{error:?}");
        assert!(message(error).contains("not a DICOM file"));
    }
}

#[test]
fn jpeg_2000_is_refused_with_its_transfer_syntax() {
    let mut object = xa_object(&cine());
    object.update_meta(|meta| meta.transfer_syntax = uids::JPEG2000.into());
    object.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OB,
        PixelFragmentSequence::new(Vec::<u32>::new(), vec![vec![0xFFu8, 0x4F, 0xFF, 0x51]]),
    ));
    let error = read_cine_file(NAME, &part10_bytes(&object)).unwrap_err();
    assert!(
        matches!(error, DicomError::UnsupportedTransferSyntax { .. }),
        "{error:?}"
    );
    let text = message(error);
    assert!(
        text.contains("1.2.840.10008.1.2.4.91") && text.contains("JPEG 2000"),
        "{text}"
    );
}

#[test]
fn colour_and_32_bit_pixels_are_refused() {
    let mut colour = xa_object(&cine());
    colour.put(DataElement::new(
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        PrimitiveValue::from("RGB"),
    ));
    colour.put(DataElement::new(
        tags::SAMPLES_PER_PIXEL,
        VR::US,
        PrimitiveValue::from(3u16),
    ));
    let error = read_cine_file(NAME, &part10_bytes(&colour)).unwrap_err();
    assert!(matches!(error, DicomError::Colour { .. }), "{error:?}");
    assert!(message(error).contains("colour images (RGB"));

    let mut wide = xa_object(&cine());
    for tag in [tags::BITS_ALLOCATED, tags::BITS_STORED] {
        wide.put(DataElement::new(tag, VR::US, PrimitiveValue::from(32u16)));
    }
    let error = read_cine_file(NAME, &part10_bytes(&wide)).unwrap_err();
    assert!(matches!(error, DicomError::BitDepth { .. }), "{error:?}");
    assert!(message(error).contains("32-bit pixels"));
}

#[test]
fn truncated_files_are_named() {
    let bytes = write_xa(&cine());
    // Cut inside the pixel data, and inside the header.
    for keep in [bytes.len() - 100, bytes.len() / 2, 700] {
        let error = read_cine_file(NAME, &bytes[..keep]).unwrap_err();
        assert!(
            matches!(error, DicomError::Truncated { .. }),
            "{keep}: {error:?}"
        );
        assert!(message(error).contains("truncated"));
    }
}

#[test]
fn planes_with_different_frame_counts_are_not_paired() {
    let mut short = cine();
    short.frames.truncate(2);
    short.patient = PatientIdentity::fictional();
    let read = |plane, name: &str, cine: &XaCine| {
        PlaneSeries::from_files(
            plane,
            name,
            vec![read_cine_file(name, &write_xa(cine)).unwrap()],
        )
        .unwrap()
    };
    let a = read(Plane::A, "a.dcm", &cine());
    let b = read(Plane::B, "b.dcm", &short);
    let error = pair_frames(&a, &b).unwrap_err();
    assert!(matches!(
        error,
        PairingError::FrameCounts {
            frames_a: 3,
            frames_b: 2,
            ..
        }
    ));
    let text = error.to_string();
    assert!(text.contains("a.dcm") && text.contains("b.dcm"), "{text}");
    // What was loaded before is untouched and still usable.
    assert_eq!(a.count(), 3);
}
