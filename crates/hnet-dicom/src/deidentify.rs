//! Patient identifiers: which a file carries, and removing them. The reader
//! ([`crate::read_cine_file`]) keeps none of them, so that nothing exported from what it read
//! (datasets, force traces) can carry one; DICOM objects written out go through [`deidentify`].
//!
//! The attributes are the identifying ones of DICOM's Basic Application Level Confidentiality
//! Profile (PS3.15 E.1) that XA/RF headers commonly hold. Sequences inside the data set are not
//! searched; private attributes (odd groups), which may hold anything, are removed too.

use dicom_core::Tag;
use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;

/// The identifying attributes and their keywords.
pub const PATIENT_IDENTIFIERS: [(Tag, &str); 24] = [
    (tags::PATIENT_NAME, "PatientName"),
    (tags::PATIENT_ID, "PatientID"),
    (tags::ISSUER_OF_PATIENT_ID, "IssuerOfPatientID"),
    // Other Patient IDs and Medical Record Locator are retired (hence no `tags` constant) but
    // still found in older files.
    (Tag(0x0010, 0x1000), "OtherPatientIDs"),
    (tags::OTHER_PATIENT_NAMES, "OtherPatientNames"),
    (tags::PATIENT_BIRTH_DATE, "PatientBirthDate"),
    (tags::PATIENT_BIRTH_TIME, "PatientBirthTime"),
    (tags::PATIENT_ADDRESS, "PatientAddress"),
    (tags::PATIENT_TELEPHONE_NUMBERS, "PatientTelephoneNumbers"),
    (tags::PATIENT_MOTHER_BIRTH_NAME, "PatientMotherBirthName"),
    (Tag(0x0010, 0x1090), "MedicalRecordLocator"),
    (tags::ACCESSION_NUMBER, "AccessionNumber"),
    (tags::STUDY_ID, "StudyID"),
    (tags::INSTITUTION_NAME, "InstitutionName"),
    (tags::INSTITUTION_ADDRESS, "InstitutionAddress"),
    (
        tags::INSTITUTIONAL_DEPARTMENT_NAME,
        "InstitutionalDepartmentName",
    ),
    (tags::STATION_NAME, "StationName"),
    (tags::DEVICE_SERIAL_NUMBER, "DeviceSerialNumber"),
    (tags::REFERRING_PHYSICIAN_NAME, "ReferringPhysicianName"),
    (tags::PERFORMING_PHYSICIAN_NAME, "PerformingPhysicianName"),
    (
        tags::NAME_OF_PHYSICIANS_READING_STUDY,
        "NameOfPhysiciansReadingStudy",
    ),
    (tags::OPERATORS_NAME, "OperatorsName"),
    (tags::REQUESTING_PHYSICIAN, "RequestingPhysician"),
    (tags::PHYSICIANS_OF_RECORD, "PhysiciansOfRecord"),
];

/// The keywords of the identifying attributes `object` holds (and `private attributes` when it
/// has any).
pub fn identifiers_present(object: &InMemDicomObject) -> Vec<&'static str> {
    let mut found: Vec<&'static str> = PATIENT_IDENTIFIERS
        .iter()
        .filter(|(tag, _)| object.element_opt(*tag).ok().flatten().is_some())
        .map(|(_, keyword)| *keyword)
        .collect();
    if object.tags().any(is_private) {
        found.push("private attributes");
    }
    found
}

/// Removes every identifying attribute and every private attribute from `object`; returns what
/// was removed, as [`identifiers_present`] names it.
pub fn deidentify(object: &mut InMemDicomObject) -> Vec<&'static str> {
    let removed = identifiers_present(object);
    for (tag, _) in PATIENT_IDENTIFIERS {
        object.remove_element(tag);
    }
    let private: Vec<Tag> = object.tags().filter(|t| is_private(*t)).collect();
    for tag in private {
        object.remove_element(tag);
    }
    removed
}

/// Private attributes have odd group numbers.
fn is_private(tag: Tag) -> bool {
    tag.group() % 2 == 1
}
