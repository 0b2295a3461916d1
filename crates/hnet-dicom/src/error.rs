//! Why a DICOM file could not be read: every error names the file and the reason, and keeps the
//! underlying parser's or decoder's error as its [`source`](std::error::Error::source).

/// The underlying error of a DICOM problem (dicom-rs's parser or pixel decoder, or I/O).
pub type Cause = Box<dyn std::error::Error + Send + Sync>;

/// A DICOM file that cannot be used, with the file's name.
#[derive(Debug, thiserror::Error)]
pub enum DicomError {
    /// The file could not be read from disk.
    #[error("{file}: cannot be read")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        #[source]
        cause: std::io::Error,
    },
    /// The bytes are not a DICOM Part 10 file (no `DICM` marker, or an unreadable header).
    #[error("{file}: not a DICOM file ({reason})")]
    NotDicom {
        /// The file.
        file: String,
        /// What was found instead.
        reason: String,
        /// The parser's error, when there is one.
        #[source]
        cause: Option<Cause>,
    },
    /// The file ends before its data does.
    #[error("{file}: the file is truncated ({reason})")]
    Truncated {
        /// The file.
        file: String,
        /// Where it ends.
        reason: String,
        /// The parser's error, when there is one.
        #[source]
        cause: Option<Cause>,
    },
    /// The pixel data is compressed in a transfer syntax this build cannot decode.
    #[error(
        "{file}: transfer syntax {uid} ({name}) is not supported: export the series uncompressed \
         or as JPEG baseline/lossless"
    )]
    UnsupportedTransferSyntax {
        /// The file.
        file: String,
        /// The transfer syntax UID.
        uid: String,
        /// Its name in the DICOM standard (or `unknown`).
        name: String,
    },
    /// Colour (RGB, YBR, palette) images: H-Net reads monochrome X-ray frames.
    #[error(
        "{file}: colour images ({photometric}, {samples} samples per pixel) are not supported: \
         X-ray frames are MONOCHROME1 or MONOCHROME2"
    )]
    Colour {
        /// The file.
        file: String,
        /// Its Photometric Interpretation.
        photometric: String,
        /// Its Samples per Pixel.
        samples: u16,
    },
    /// Pixels of more than 16 bits (or fewer than 8).
    #[error(
        "{file}: {bits_allocated}-bit pixels ({bits_stored} bits stored) are not supported: 8 to \
         16 bits are"
    )]
    BitDepth {
        /// The file.
        file: String,
        /// Bits Allocated.
        bits_allocated: u16,
        /// Bits Stored.
        bits_stored: u16,
    },
    /// A required attribute is missing or unreadable.
    #[error("{file}: {attribute} {problem}")]
    Attribute {
        /// The file.
        file: String,
        /// The attribute's keyword (`Rows`, `PixelData`, ...).
        attribute: &'static str,
        /// What is wrong with it.
        problem: String,
        /// The conversion error, when there is one.
        #[source]
        cause: Option<Cause>,
    },
    /// The pixel data could not be decoded.
    #[error("{file}: the pixel data cannot be decoded")]
    Decode {
        /// The file.
        file: String,
        /// The decoder's error.
        #[source]
        cause: Cause,
    },
    /// The files of one series disagree (image size, bit depth).
    #[error("{file}: {problem} (the series' first file, {first}, {first_value})")]
    Inconsistent {
        /// The file that disagrees.
        file: String,
        /// How it differs.
        problem: String,
        /// The series' first file.
        first: String,
        /// The first file's value.
        first_value: String,
    },
    /// A folder given as a series holds no DICOM files.
    #[error("{file}: the folder holds no files")]
    EmptyFolder {
        /// The folder.
        file: String,
    },
}

impl DicomError {
    /// The file (or folder) concerned.
    pub fn file(&self) -> &str {
        match self {
            DicomError::Io { file, .. }
            | DicomError::NotDicom { file, .. }
            | DicomError::Truncated { file, .. }
            | DicomError::UnsupportedTransferSyntax { file, .. }
            | DicomError::Colour { file, .. }
            | DicomError::BitDepth { file, .. }
            | DicomError::Attribute { file, .. }
            | DicomError::Decode { file, .. }
            | DicomError::Inconsistent { file, .. }
            | DicomError::EmptyFolder { file } => file,
        }
    }
}
