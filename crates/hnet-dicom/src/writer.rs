//! Writing XA multi-frame files (X-Ray Angiographic Image Storage, explicit VR little endian):
//! the test suite's input, made from frames the twin renders ([`crate::twin_cine`]), and what a
//! future `hnet` command may export. Each file carries one plane's C-arm geometry, frame time,
//! window and, to be realistic, the patient identifiers a hospital file has (made up ones).

use dicom_core::value::PrimitiveValue;
use dicom_core::{DataElement, Tag, VR, dicom_value};
use dicom_dictionary_std::{tags, uids};
use dicom_object::meta::FileMetaTableBuilder;
use dicom_object::{FileDicomObject, InMemDicomObject};
use hnet_twin::simulator::carm::CArm;
use hnet_units::ImageSize;

use crate::frames::{ModalityLut, Monochrome};
use crate::geometry::Plane;

/// The patient module of a written file (the tests check none of it comes out again).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PatientIdentity {
    /// Patient's Name, `FAMILY^GIVEN`.
    pub name: String,
    /// Patient ID.
    pub id: String,
    /// Patient's Birth Date, `YYYYMMDD`.
    pub birth_date: String,
    /// Accession Number.
    pub accession: String,
    /// Institution Name.
    pub institution: String,
}

impl PatientIdentity {
    /// A made-up patient, easy to search for in exported files.
    pub fn fictional() -> Self {
        Self {
            name: "DOE^JANE".into(),
            id: "PID-0042-TWIN".into(),
            birth_date: "19611224".into(),
            accession: "ACC-7731".into(),
            institution: "Twin General Hospital".into(),
        }
    }
}

/// One plane's cine to write.
#[derive(Debug, Clone, PartialEq)]
pub struct XaCine {
    /// Which plane (Image Type `BIPLANE A` / `BIPLANE B`).
    pub plane: Plane,
    /// Frame size, pixels.
    pub size: ImageSize,
    /// Bits Stored, 1-16; 8 bits are allocated up to 8, else 16.
    pub bits_stored: u16,
    /// Pixel Representation 1 (two's complement; `frames` then hold the values' bit patterns).
    pub signed: bool,
    /// MONOCHROME1 or MONOCHROME2.
    pub monochrome: Monochrome,
    /// The frames' stored values, row-major.
    pub frames: Vec<Vec<u16>>,
    /// The C-arm written as Positioner angles, distances and Imager Pixel Spacing; `None` writes
    /// no geometry attribute.
    pub carm: Option<CArm>,
    /// Frame Time, ms (also the Frame Increment Pointer's target); `None` writes none.
    pub frame_time_ms: Option<f64>,
    /// Acquisition DateTime (`YYYYMMDDHHMMSS.FFFFFF`).
    pub acquisition_date_time: Option<String>,
    /// Window Center/Width pairs (several, as scanners write them).
    pub windows: Vec<(f64, f64)>,
    /// Rescale Slope/Intercept; `None` writes none.
    pub rescale: Option<ModalityLut>,
    /// The patient module.
    pub patient: PatientIdentity,
    /// Seeds the UIDs.
    pub uid_seed: u64,
}

/// A decimal string value of several numbers.
fn decimals(values: &[f64]) -> PrimitiveValue {
    PrimitiveValue::Strs(values.iter().map(|v| format!("{v}")).collect())
}

/// A UID under the `2.25` (UUID-derived) root, deterministic for `seed` and `part`.
fn uid(seed: u64, part: u64) -> String {
    format!(
        "2.25.{}{:04}",
        seed.wrapping_mul(7919).wrapping_add(1),
        part
    )
}

/// The data set and file meta group of `cine`.
pub fn xa_object(cine: &XaCine) -> FileDicomObject<InMemDicomObject> {
    let mut object = InMemDicomObject::new_empty();
    let mut put = |tag: Tag, vr: VR, value: PrimitiveValue| {
        object.put(DataElement::new(tag, vr, value));
    };
    let text = |s: &str| PrimitiveValue::from(s);
    let sop_instance = uid(cine.uid_seed, 3);
    let plane = format!("BIPLANE {}", cine.plane.name());
    put(
        tags::IMAGE_TYPE,
        VR::CS,
        dicom_value!(Strs, ["ORIGINAL", "PRIMARY", plane.as_str()]),
    );
    put(
        tags::SOP_CLASS_UID,
        VR::UI,
        text(uids::X_RAY_ANGIOGRAPHIC_IMAGE_STORAGE),
    );
    put(tags::SOP_INSTANCE_UID, VR::UI, text(&sop_instance));
    put(tags::STUDY_DATE, VR::DA, text("20240501"));
    put(tags::MODALITY, VR::CS, text("XA"));
    put(tags::MANUFACTURER, VR::LO, text("H-Net Studio twin"));
    put(
        tags::INSTITUTION_NAME,
        VR::LO,
        text(&cine.patient.institution),
    );
    put(
        tags::ACCESSION_NUMBER,
        VR::SH,
        text(&cine.patient.accession),
    );
    put(tags::REFERRING_PHYSICIAN_NAME, VR::PN, text("WHO^DOCTOR"));
    put(tags::PATIENT_NAME, VR::PN, text(&cine.patient.name));
    put(tags::PATIENT_ID, VR::LO, text(&cine.patient.id));
    put(
        tags::PATIENT_BIRTH_DATE,
        VR::DA,
        text(&cine.patient.birth_date),
    );
    put(tags::PATIENT_SEX, VR::CS, text("F"));
    put(
        tags::STUDY_INSTANCE_UID,
        VR::UI,
        text(&uid(cine.uid_seed, 1)),
    );
    put(
        tags::SERIES_INSTANCE_UID,
        VR::UI,
        text(&uid(cine.uid_seed, 2)),
    );
    put(tags::STUDY_ID, VR::SH, text("1"));
    put(tags::SERIES_NUMBER, VR::IS, text("1"));
    put(tags::INSTANCE_NUMBER, VR::IS, text("1"));
    if let Some(when) = &cine.acquisition_date_time {
        put(tags::ACQUISITION_DATE_TIME, VR::DT, text(when));
    }
    put(tags::POSITIONER_MOTION, VR::CS, text("STATIC"));
    if let Some(carm) = &cine.carm {
        put(
            tags::POSITIONER_PRIMARY_ANGLE,
            VR::DS,
            decimals(&[carm.primary_deg]),
        );
        put(
            tags::POSITIONER_SECONDARY_ANGLE,
            VR::DS,
            decimals(&[carm.secondary_deg]),
        );
        put(
            tags::DISTANCE_SOURCE_TO_DETECTOR,
            VR::DS,
            decimals(&[carm.source_to_detector_mm]),
        );
        put(
            tags::DISTANCE_SOURCE_TO_PATIENT,
            VR::DS,
            decimals(&[carm.source_to_isocentre_mm]),
        );
        put(
            tags::IMAGER_PIXEL_SPACING,
            VR::DS,
            decimals(&[carm.pixel_pitch_mm, carm.pixel_pitch_mm]),
        );
    }
    if let Some(ms) = cine.frame_time_ms {
        put(tags::FRAME_TIME, VR::DS, decimals(&[ms]));
        put(
            tags::FRAME_INCREMENT_POINTER,
            VR::AT,
            PrimitiveValue::Tags([tags::FRAME_TIME].into_iter().collect()),
        );
    }
    let bits_allocated: u16 = if cine.bits_stored <= 8 { 8 } else { 16 };
    let us = |v: u16| PrimitiveValue::from(v);
    put(tags::SAMPLES_PER_PIXEL, VR::US, us(1));
    let photometric = match cine.monochrome {
        Monochrome::One => "MONOCHROME1",
        Monochrome::Two => "MONOCHROME2",
    };
    put(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, text(photometric));
    put(
        tags::NUMBER_OF_FRAMES,
        VR::IS,
        text(&cine.frames.len().to_string()),
    );
    put(tags::ROWS, VR::US, us(cine.size.height as u16));
    put(tags::COLUMNS, VR::US, us(cine.size.width as u16));
    put(tags::BITS_ALLOCATED, VR::US, us(bits_allocated));
    put(tags::BITS_STORED, VR::US, us(cine.bits_stored));
    put(tags::HIGH_BIT, VR::US, us(cine.bits_stored - 1));
    put(
        tags::PIXEL_REPRESENTATION,
        VR::US,
        us(u16::from(cine.signed)),
    );
    if !cine.windows.is_empty() {
        let (centres, widths): (Vec<f64>, Vec<f64>) = cine.windows.iter().copied().unzip();
        put(tags::WINDOW_CENTER, VR::DS, decimals(&centres));
        put(tags::WINDOW_WIDTH, VR::DS, decimals(&widths));
    }
    if let Some(lut) = cine.rescale {
        put(tags::RESCALE_INTERCEPT, VR::DS, decimals(&[lut.intercept]));
        put(tags::RESCALE_SLOPE, VR::DS, decimals(&[lut.slope]));
    }
    let samples = cine.frames.iter().flatten().copied();
    let pixel_data = if bits_allocated == 8 {
        (
            VR::OB,
            PrimitiveValue::U8(samples.map(|v| v as u8).collect()),
        )
    } else {
        (VR::OW, PrimitiveValue::U16(samples.collect()))
    };
    put(tags::PIXEL_DATA, pixel_data.0, pixel_data.1);
    object
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)
                .media_storage_sop_class_uid(uids::X_RAY_ANGIOGRAPHIC_IMAGE_STORAGE)
                .media_storage_sop_instance_uid(sop_instance),
        )
        .expect("a complete file meta group")
}

/// `object` as Part 10 bytes (preamble, `DICM`, file meta group, data set).
pub fn part10_bytes(object: &FileDicomObject<InMemDicomObject>) -> Vec<u8> {
    let mut bytes = Vec::new();
    object
        .write_all(&mut bytes)
        .expect("writing a data set to memory");
    bytes
}

/// `cine` as a Part 10 file's bytes.
pub fn write_xa(cine: &XaCine) -> Vec<u8> {
    part10_bytes(&xa_object(cine))
}
