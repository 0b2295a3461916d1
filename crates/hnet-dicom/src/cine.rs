//! A biplane cine: plane A and plane B paired frame by frame, and what the user must be told
//! about them (geometry the headers lacked, frames paired by index or apart in time). The one
//! joining of two series that `hnet import`, `hnet trace` and the page share.

use crate::geometry::Plane;
use crate::pairing::{Pairing, PairingError, pair_frames};
use crate::series::PlaneSeries;
use crate::window::WindowLevel;

/// Plane A and plane B and their frame pairs.
#[derive(Debug, Clone, PartialEq)]
pub struct BiplaneCine {
    /// Plane A and plane B.
    pub planes: [PlaneSeries; 2],
    /// One pair per frame.
    pub pairing: Pairing,
}

impl BiplaneCine {
    /// Pairs two planes' series; the error names both series and their frame counts.
    pub fn pair(plane_a: PlaneSeries, plane_b: PlaneSeries) -> Result<Self, PairingError> {
        let pairing = pair_frames(&plane_a, &plane_b)?;
        Ok(Self {
            planes: [plane_a, plane_b],
            pairing,
        })
    }

    /// Number of frame pairs.
    pub fn frame_count(&self) -> usize {
        self.pairing.pairs.len()
    }

    /// What the user should know before trusting the geometry or the timing: each plane's
    /// missing geometry attributes (and the default used for them), then the pairing warnings.
    pub fn notes(&self) -> Vec<String> {
        self.planes
            .iter()
            .filter_map(missing_geometry_note)
            .chain(self.pairing.warnings.iter().map(ToString::to_string))
            .collect()
    }

    /// Frame `frame` (0-based) of `plane` as 8-bit grey under `window`, row-major at the
    /// series' size; `None` past the last frame.
    pub fn grey_frame(&self, plane: Plane, frame: usize, window: WindowLevel) -> Option<Vec<u8>> {
        self.series(plane).grey_frame(frame, window)
    }

    /// The series of `plane`.
    pub fn series(&self, plane: Plane) -> &PlaneSeries {
        match plane {
            Plane::A => &self.planes[0],
            Plane::B => &self.planes[1],
        }
    }
}

/// The geometry attributes a plane's headers lacked and the default taken for them, if any.
pub fn missing_geometry_note(series: &PlaneSeries) -> Option<String> {
    let missing = &series.geometry.missing;
    if missing.is_empty() {
        return None;
    }
    let names: Vec<&str> = missing.iter().map(|tag| tag.keyword()).collect();
    Some(format!(
        "plane {} ({}) lacks {}: the default {} geometry is used for them",
        series.plane.name(),
        series.source,
        names.join(", "),
        match series.plane {
            Plane::A => "frontal",
            Plane::B => "lateral",
        },
    ))
}
