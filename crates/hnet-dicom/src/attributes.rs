//! Reading header values: the one place that turns a data element into a number or text.

use dicom_core::Tag;
use dicom_object::DefaultDicomObject;

use crate::error::DicomError;

/// A parsed Part 10 file (dicom-rs's in-memory object with its file meta group).
pub type DicomObject = DefaultDicomObject;

/// The attribute `tag`'s values as numbers, `None` when it is absent or empty.
pub fn numbers(
    object: &DicomObject,
    file: &str,
    tag: Tag,
    attribute: &'static str,
) -> Result<Option<Vec<f64>>, DicomError> {
    let Some(element) = object.element_opt(tag).ok().flatten() else {
        return Ok(None);
    };
    if element.to_str().is_ok_and(|t| {
        t.trim_matches(|c: char| c == '\0' || c.is_whitespace())
            .is_empty()
    }) {
        return Ok(None);
    }
    element
        .to_multi_float64()
        .map(|values| Some(values).filter(|v| !v.is_empty()))
        .map_err(|e| DicomError::Attribute {
            file: file.into(),
            attribute,
            problem: "is not a number".into(),
            cause: Some(Box::new(e)),
        })
}

/// The attribute's first value as a number, `None` when absent.
pub fn number(
    object: &DicomObject,
    file: &str,
    tag: Tag,
    attribute: &'static str,
) -> Result<Option<f64>, DicomError> {
    Ok(numbers(object, file, tag, attribute)?.and_then(|v| v.first().copied()))
}

/// A required whole number (Rows, Columns, Bits Allocated, ...).
pub fn required_count(
    object: &DicomObject,
    file: &str,
    tag: Tag,
    attribute: &'static str,
) -> Result<u32, DicomError> {
    let value = number(object, file, tag, attribute)?.ok_or_else(|| DicomError::Attribute {
        file: file.into(),
        attribute,
        problem: "is missing".into(),
        cause: None,
    })?;
    if value < 0.0 || value.fract() != 0.0 || value > f64::from(u32::MAX) {
        return Err(DicomError::Attribute {
            file: file.into(),
            attribute,
            problem: format!("is {value}, not a whole number"),
            cause: None,
        });
    }
    Ok(value as u32)
}

/// The attribute's text, trimmed of DICOM's padding, `None` when absent or empty.
pub fn text(object: &DicomObject, tag: Tag) -> Option<String> {
    let element = object.element_opt(tag).ok().flatten()?;
    let text = element.to_str().ok()?;
    let text = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    (!text.is_empty()).then(|| text.to_string())
}
