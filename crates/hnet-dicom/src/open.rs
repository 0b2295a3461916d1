//! Reading series from disk (natively; the page passes bytes to [`crate::read_cine_file`]): a
//! plane is one DICOM file, or a folder whose files are its frames or parts of them.

use std::path::Path;

use crate::error::DicomError;
use crate::file::{CineFile, read_cine_file};
use crate::geometry::Plane;
use crate::series::PlaneSeries;

/// Reads the file at `path`; errors name it.
pub fn open_cine_file(path: &Path) -> Result<CineFile, DicomError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|cause| DicomError::Io {
        file: name.clone(),
        cause,
    })?;
    read_cine_file(&name, &bytes)
}

/// Reads plane `plane`'s series from a file, or from every file of a folder (in name order,
/// unless all have an Instance Number; hidden files and `DICOMDIR` are skipped).
pub fn open_series(plane: Plane, path: &Path) -> Result<PlaneSeries, DicomError> {
    let name = path.display().to_string();
    let files = if path.is_dir() {
        let io = |cause| DicomError::Io {
            file: name.clone(),
            cause,
        };
        let mut paths = Vec::new();
        for entry in std::fs::read_dir(path).map_err(io)? {
            let entry_path = entry.map_err(io)?.path();
            let file_name = entry_path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            if entry_path.is_file() && !file_name.starts_with('.') && file_name != "DICOMDIR" {
                paths.push(entry_path);
            }
        }
        paths.sort();
        paths
            .iter()
            .map(|p| open_cine_file(p))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        vec![open_cine_file(path)?]
    };
    PlaneSeries::from_files(plane, &name, files)
}
