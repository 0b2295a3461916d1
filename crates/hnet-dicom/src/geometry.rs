//! A plane's C-arm geometry from the XA/RF headers, mapped onto the twin's [`CArm`]:
//!
//! | attribute | tag | `CArm` field | unit |
//! | --- | --- | --- | --- |
//! | Positioner Primary Angle | (0018,1510) | `primary_deg` (LAO +, RAO -) | degrees |
//! | Positioner Secondary Angle | (0018,1511) | `secondary_deg` (cranial +, caudal -) | degrees |
//! | Distance Source to Detector | (0018,1110) | `source_to_detector_mm` | mm |
//! | Distance Source to Patient | (0018,1111) | `source_to_isocentre_mm` | mm |
//! | Imager Pixel Spacing | (0018,1164) | `pixel_pitch_mm` (at the detector) | mm |
//! | Rows, Columns | (0028,0010/0011) | `image_size` | pixels |
//!
//! DICOM's angle conventions are the twin's: the primary angle is positive towards LAO, the
//! secondary towards cranial. Without Imager Pixel Spacing, Pixel Spacing (0028,0030), which XA
//! calibrates at the isocentre, is scaled to the detector by the magnification SID/SOD. A missing
//! attribute takes the plane's default ([`Plane::default_carm`]) and is listed, so that callers
//! can say which geometry is assumed.

use dicom_dictionary_std::tags;
use hnet_twin::simulator::carm::CArm;
use hnet_units::ImageSize;

use crate::attributes::{DicomObject, numbers};
use crate::error::DicomError;

/// Plane A (frontal) or plane B (lateral) of a biplane system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Plane {
    /// Plane A: by default frontal (PA, both angles 0).
    A,
    /// Plane B: by default left lateral (LAO 90).
    B,
}

impl Plane {
    /// Both planes.
    pub const BOTH: [Plane; 2] = [Plane::A, Plane::B];

    /// `A` or `B`.
    pub fn name(self) -> &'static str {
        match self {
            Plane::A => "A",
            Plane::B => "B",
        }
    }

    /// The geometry assumed where the headers say nothing: the twin's cardiac C-arm, frontal for
    /// plane A and left lateral for plane B, at `size`.
    pub fn default_carm(self, size: ImageSize) -> CArm {
        let primary_deg = match self {
            Plane::A => 0.0,
            Plane::B => 90.0,
        };
        CArm::cardiac(primary_deg, 0.0, size)
    }
}

/// A geometry attribute that a file lacks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum GeometryTag {
    /// Positioner Primary Angle (0018,1510).
    PositionerPrimaryAngle,
    /// Positioner Secondary Angle (0018,1511).
    PositionerSecondaryAngle,
    /// Distance Source to Detector (0018,1110).
    DistanceSourceToDetector,
    /// Distance Source to Patient (0018,1111).
    DistanceSourceToPatient,
    /// Imager Pixel Spacing (0018,1164), and Pixel Spacing (0028,0030) too.
    ImagerPixelSpacing,
}

impl GeometryTag {
    /// The attribute's keyword in the DICOM standard.
    pub fn keyword(self) -> &'static str {
        match self {
            GeometryTag::PositionerPrimaryAngle => "PositionerPrimaryAngle",
            GeometryTag::PositionerSecondaryAngle => "PositionerSecondaryAngle",
            GeometryTag::DistanceSourceToDetector => "DistanceSourceToDetector",
            GeometryTag::DistanceSourceToPatient => "DistanceSourceToPatient",
            GeometryTag::ImagerPixelSpacing => "ImagerPixelSpacing",
        }
    }
}

impl std::fmt::Display for GeometryTag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.keyword())
    }
}

/// The geometry attributes of one file, as found (each `None` when absent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeaderGeometry {
    /// Positioner Primary Angle, degrees.
    pub primary_deg: Option<f64>,
    /// Positioner Secondary Angle, degrees.
    pub secondary_deg: Option<f64>,
    /// Distance Source to Detector, mm.
    pub source_to_detector_mm: Option<f64>,
    /// Distance Source to Patient (the isocentre), mm.
    pub source_to_patient_mm: Option<f64>,
    /// Imager Pixel Spacing (row spacing, column spacing) at the detector, mm.
    pub imager_pixel_spacing_mm: Option<[f64; 2]>,
    /// Pixel Spacing (row spacing, column spacing) at the isocentre, mm.
    pub pixel_spacing_mm: Option<[f64; 2]>,
    /// Columns x Rows, pixels.
    pub image_size: ImageSize,
}

/// A plane's C-arm and the attributes for which the default was used.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneGeometry {
    /// The geometry, from the headers where present.
    pub carm: CArm,
    /// Attributes that were missing (empty when the headers gave everything).
    pub missing: Vec<GeometryTag>,
}

impl HeaderGeometry {
    /// Reads the geometry attributes of `object` (`file` names it in errors), whose frames are
    /// `image_size`.
    pub fn read(
        object: &DicomObject,
        file: &str,
        image_size: ImageSize,
    ) -> Result<Self, DicomError> {
        let positive = |v: Option<f64>| v.filter(|v| v.is_finite() && *v > 0.0);
        let first = |tag, name| -> Result<Option<f64>, DicomError> {
            Ok(numbers(object, file, tag, name)?
                .and_then(|v| v.first().copied())
                .filter(|v| v.is_finite()))
        };
        let spacing = |tag, name| -> Result<Option<[f64; 2]>, DicomError> {
            Ok(numbers(object, file, tag, name)?.and_then(|v| match v[..] {
                [row, column, ..] if row > 0.0 && column > 0.0 => Some([row, column]),
                [both] if both > 0.0 => Some([both, both]),
                _ => None,
            }))
        };
        Ok(Self {
            primary_deg: first(tags::POSITIONER_PRIMARY_ANGLE, "PositionerPrimaryAngle")?,
            secondary_deg: first(tags::POSITIONER_SECONDARY_ANGLE, "PositionerSecondaryAngle")?,
            source_to_detector_mm: positive(first(
                tags::DISTANCE_SOURCE_TO_DETECTOR,
                "DistanceSourceToDetector",
            )?),
            source_to_patient_mm: positive(first(
                tags::DISTANCE_SOURCE_TO_PATIENT,
                "DistanceSourceToPatient",
            )?),
            imager_pixel_spacing_mm: spacing(tags::IMAGER_PIXEL_SPACING, "ImagerPixelSpacing")?,
            pixel_spacing_mm: spacing(tags::PIXEL_SPACING, "PixelSpacing")?,
            image_size,
        })
    }

    /// The C-arm of `plane`: each attribute from the header, or the plane's default where it is
    /// missing. Non-square detector pixels take the mean of row and column spacing.
    pub fn carm(&self, plane: Plane) -> PlaneGeometry {
        let default = plane.default_carm(self.image_size);
        let mut missing = Vec::new();
        let mut take = |value: Option<f64>, tag, default: f64| {
            value.unwrap_or_else(|| {
                missing.push(tag);
                default
            })
        };
        let primary_deg = take(
            self.primary_deg,
            GeometryTag::PositionerPrimaryAngle,
            default.primary_deg,
        );
        let secondary_deg = take(
            self.secondary_deg,
            GeometryTag::PositionerSecondaryAngle,
            default.secondary_deg,
        );
        let source_to_detector_mm = take(
            self.source_to_detector_mm,
            GeometryTag::DistanceSourceToDetector,
            default.source_to_detector_mm,
        );
        let source_to_isocentre_mm = take(
            self.source_to_patient_mm,
            GeometryTag::DistanceSourceToPatient,
            default.source_to_isocentre_mm,
        );
        let mean = |[row, column]: [f64; 2]| (row + column) / 2.0;
        let magnification = source_to_detector_mm / source_to_isocentre_mm;
        let pitch = self
            .imager_pixel_spacing_mm
            .map(mean)
            .or(self.pixel_spacing_mm.map(|s| mean(s) * magnification));
        let pixel_pitch_mm = take(
            pitch,
            GeometryTag::ImagerPixelSpacing,
            default.pixel_pitch_mm,
        );
        PlaneGeometry {
            carm: CArm {
                primary_deg,
                secondary_deg,
                source_to_isocentre_mm,
                source_to_detector_mm,
                pixel_pitch_mm,
                image_size: self.image_size,
            },
            missing,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_attributes_take_the_planes_default_and_are_listed() {
        let size = ImageSize::square(32);
        let header = HeaderGeometry {
            primary_deg: Some(-30.0),
            secondary_deg: None,
            source_to_detector_mm: Some(1100.0),
            source_to_patient_mm: Some(800.0),
            imager_pixel_spacing_mm: None,
            pixel_spacing_mm: Some([0.2, 0.2]),
            image_size: size,
        };
        let b = header.carm(Plane::B);
        assert_eq!(b.carm.primary_deg, -30.0);
        assert_eq!(b.carm.secondary_deg, 0.0);
        assert!((b.carm.pixel_pitch_mm - 0.2 * 1100.0 / 800.0).abs() < 1e-12);
        assert_eq!(b.missing, [GeometryTag::PositionerSecondaryAngle]);
        let none = HeaderGeometry {
            primary_deg: None,
            source_to_detector_mm: None,
            source_to_patient_mm: None,
            pixel_spacing_mm: None,
            ..header
        };
        assert_eq!(
            none.carm(Plane::B).carm,
            CArm::cardiac(90.0, 0.0, ImageSize::square(32))
        );
        assert_eq!(none.carm(Plane::A).missing.len(), 5);
    }
}
