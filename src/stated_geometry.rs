//! The C-arm geometry a user states for an uploaded pair: each view's angles and the distances a
//! DICOM header would give (source to isocentre, source to detector, the detector's width). With
//! it, the 3D step reads the pair with its real C-arms and its reprojection error checks
//! something; without it the page assumes its default biplane and says so.

use hnet_twin::simulator::carm::{Biplane, CArm};

use crate::imaging::WORK_SIZE;

/// The geometry as typed: `[primary, secondary]` angles of views A and B (degrees), and the
/// distances both planes share (millimetres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StatedGeometry {
    /// `[primary, secondary]` of view A and of view B, degrees (the DICOM Positioner Primary and
    /// Secondary Angles: right/left anterior oblique, cranial/caudal).
    pub views_deg: [[f64; 2]; 2],
    /// Source (focal spot) to isocentre, mm.
    pub source_to_isocentre_mm: f64,
    /// Source to detector, mm.
    pub source_to_detector_mm: f64,
    /// The width of the detector area the image shows, mm.
    pub detector_width_mm: f64,
}

/// The fields of the form, in [`StatedGeometry::FIELDS`] order.
pub type GeometryFields = [String; 7];

/// A stated value the page cannot use, named by its field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryInputError {
    /// Not a number.
    #[error("{field}: `{text}` is not a number")]
    NotANumber {
        /// The field's label.
        field: &'static str,
        /// What was typed.
        text: String,
    },
    /// A number outside what a C-arm can have.
    #[error("{field}: {value} is outside {range}")]
    OutOfRange {
        /// The field's label.
        field: &'static str,
        /// The value.
        value: f64,
        /// The accepted range, `low to high` in the field's unit.
        range: String,
    },
    /// The detector is not beyond the isocentre.
    #[error(
        "source to detector ({detector} mm) must be longer than source to isocentre ({isocentre} \
         mm): the detector lies beyond the patient"
    )]
    DetectorBeforeIsocentre {
        /// Source to detector, mm.
        detector: f64,
        /// Source to isocentre, mm.
        isocentre: f64,
    },
}

impl StatedGeometry {
    /// The form's fields: label, and the range a value must lie in (inclusive).
    pub const FIELDS: [(&'static str, [f64; 2]); 7] = [
        ("view A primary angle (°)", [-180.0, 180.0]),
        ("view A secondary angle (°)", [-90.0, 90.0]),
        ("view B primary angle (°)", [-180.0, 180.0]),
        ("view B secondary angle (°)", [-90.0, 90.0]),
        ("source to isocentre (mm)", [200.0, 2000.0]),
        ("source to detector (mm)", [300.0, 2500.0]),
        ("detector width (mm)", [20.0, 600.0]),
    ];

    /// The geometry of `views` (C-arms at [`WORK_SIZE`]; plane B's distances are taken as
    /// plane A's).
    pub fn of_views(views: &Biplane) -> Self {
        Self {
            views_deg: [views.a, views.b].map(|c| [c.primary_deg, c.secondary_deg]),
            source_to_isocentre_mm: views.a.source_to_isocentre_mm,
            source_to_detector_mm: views.a.source_to_detector_mm,
            detector_width_mm: views.a.pixel_pitch_mm * views.a.image_size.width as f64,
        }
    }

    /// The form's text for this geometry.
    pub fn fields(&self) -> GeometryFields {
        let [[a1, a2], [b1, b2]] = self.views_deg;
        [
            a1,
            a2,
            b1,
            b2,
            self.source_to_isocentre_mm,
            self.source_to_detector_mm,
            self.detector_width_mm,
        ]
        .map(|v| format!("{}", (v * 100.0).round() / 100.0))
    }

    /// Reads the form; the first field the page cannot use is named.
    pub fn parse(fields: &GeometryFields) -> Result<Self, GeometryInputError> {
        let mut values = [0.0; 7];
        for ((text, (field, [low, high])), value) in
            fields.iter().zip(Self::FIELDS).zip(&mut values)
        {
            let trimmed = text.trim();
            let v: f64 = trimmed
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| GeometryInputError::NotANumber {
                    field,
                    text: trimmed.to_string(),
                })?;
            if !(low..=high).contains(&v) {
                return Err(GeometryInputError::OutOfRange {
                    field,
                    value: v,
                    range: format!("{low} to {high}"),
                });
            }
            *value = v;
        }
        let [a1, a2, b1, b2, isocentre, detector, width] = values;
        if detector <= isocentre {
            return Err(GeometryInputError::DetectorBeforeIsocentre {
                detector,
                isocentre,
            });
        }
        Ok(Self {
            views_deg: [[a1, a2], [b1, b2]],
            source_to_isocentre_mm: isocentre,
            source_to_detector_mm: detector,
            detector_width_mm: width,
        })
    }

    /// Both C-arms at [`WORK_SIZE`], the size the page holds every pair at.
    pub fn views(&self) -> Biplane {
        let carm = |[primary_deg, secondary_deg]: [f64; 2]| CArm {
            primary_deg,
            secondary_deg,
            source_to_isocentre_mm: self.source_to_isocentre_mm,
            source_to_detector_mm: self.source_to_detector_mm,
            pixel_pitch_mm: self.detector_width_mm / WORK_SIZE.width as f64,
            image_size: WORK_SIZE,
        };
        Biplane {
            a: carm(self.views_deg[0]),
            b: carm(self.views_deg[1]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_biplane_round_trips_through_the_form() {
        let views = crate::catheter_3d::default_views();
        let stated = StatedGeometry::of_views(&views);
        let read = StatedGeometry::parse(&stated.fields()).unwrap();
        assert_eq!(read, stated);
        let back = read.views();
        for (a, b) in [(back.a, views.a), (back.b, views.b)] {
            assert_eq!(
                [a.primary_deg, a.secondary_deg],
                [b.primary_deg, b.secondary_deg]
            );
            assert!((a.pixel_pitch_mm - b.pixel_pitch_mm).abs() < 1e-12);
            assert_eq!(a.image_size, b.image_size);
        }
    }

    #[test]
    fn a_value_the_page_cannot_use_is_named() {
        let good = StatedGeometry::of_views(&crate::catheter_3d::default_views()).fields();
        let with = |index: usize, text: &str| {
            let mut fields = good.clone();
            fields[index] = text.into();
            StatedGeometry::parse(&fields).unwrap_err().to_string()
        };
        assert_eq!(
            with(0, "LAO 30"),
            "view A primary angle (°): `LAO 30` is not a number"
        );
        assert_eq!(
            with(3, "95"),
            "view B secondary angle (°): 95 is outside -90 to 90"
        );
        assert!(with(5, "700").contains("must be longer than source to isocentre"));
        assert_eq!(with(6, "NaN"), "detector width (mm): `NaN` is not a number");
        assert_eq!(with(6, "0"), "detector width (mm): 0 is outside 20 to 600");
    }
}
