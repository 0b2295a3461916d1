//! Biplane pairing: frame `i` of plane A with frame `i` of plane B. Both planes must have the
//! same number of frames (a biplane run exposes both planes at each frame time). Where both
//! planes' headers give frame times, the pairs are checked against them: pairing by time then
//! gives the same pairs, and pairs further apart than half a frame interval are reported.

use crate::geometry::Plane;
use crate::series::PlaneSeries;

/// Frames further apart than this are reported when a series has one frame only, seconds.
const SINGLE_FRAME_TOLERANCE_S: f64 = 0.02;

/// One frame pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramePair {
    /// The frame, 0-based, in both planes.
    pub frame: usize,
    /// Plane A's frame time after its first frame, seconds, when known (else plane B's).
    pub time_s: Option<f64>,
}

/// Something the caller should tell the user; the pairs are still usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PairingWarning {
    /// One plane's headers give no frame times: frames are paired by index.
    #[error("plane {} ({series}) gives no frame times: frames are paired by index", plane.name())]
    Untimed {
        /// The plane without times.
        plane: Plane,
        /// Its file or folder.
        series: String,
    },
    /// Paired frames were taken at different times.
    #[error(
        "{count} frame pairs are more than {tolerance_s:.3} s apart, the first frame {} (plane \
         A at {time_a_s:.3} s, plane B at {time_b_s:.3} s)",
        frame + 1
    )]
    Timing {
        /// The first such frame, 0-based.
        frame: usize,
        /// Its time in plane A, seconds.
        time_a_s: f64,
        /// Its time in plane B, seconds.
        time_b_s: f64,
        /// How many pairs are that far apart.
        count: usize,
        /// Half a frame interval, seconds.
        tolerance_s: f64,
    },
}

/// The two planes cannot be paired.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PairingError {
    /// The planes have different numbers of frames.
    #[error(
        "plane A ({source_a}) has {frames_a} frames but plane B ({source_b}) has {frames_b}: a \
         biplane run has one frame per plane at each time"
    )]
    FrameCounts {
        /// Plane A's file or folder.
        source_a: String,
        /// Its frames.
        frames_a: usize,
        /// Plane B's file or folder.
        source_b: String,
        /// Its frames.
        frames_b: usize,
    },
}

/// The frame pairs of a biplane run and any warnings.
#[derive(Debug, Clone, PartialEq)]
pub struct Pairing {
    /// One pair per frame.
    pub pairs: Vec<FramePair>,
    /// Whether both planes' frame times were checked.
    pub timed: bool,
    /// What the user should know.
    pub warnings: Vec<PairingWarning>,
}

/// Half the shortest interval between consecutive frames of either plane, seconds.
fn tolerance(times: [&[f64]; 2]) -> f64 {
    let shortest = times
        .iter()
        .flat_map(|t| t.windows(2).map(|w| w[1] - w[0]))
        .filter(|dt| *dt > 0.0)
        .fold(f64::INFINITY, f64::min);
    if shortest.is_finite() {
        shortest / 2.0
    } else {
        SINGLE_FRAME_TOLERANCE_S
    }
}

/// Pairs plane A's frames with plane B's.
pub fn pair_frames(a: &PlaneSeries, b: &PlaneSeries) -> Result<Pairing, PairingError> {
    if a.count() != b.count() {
        return Err(PairingError::FrameCounts {
            source_a: a.source.clone(),
            frames_a: a.count(),
            source_b: b.source.clone(),
            frames_b: b.count(),
        });
    }
    let mut warnings = Vec::new();
    let (times_a, times_b) = (a.frame_times_s.as_deref(), b.frame_times_s.as_deref());
    for (series, times) in [(a, times_a), (b, times_b)] {
        if times.is_none() && times_a.or(times_b).is_some() {
            warnings.push(PairingWarning::Untimed {
                plane: series.plane,
                series: series.source.clone(),
            });
        }
    }
    if let (Some(ta), Some(tb)) = (times_a, times_b) {
        // Absolute times where both planes give their start, else times from each first frame.
        let offset = match (a.start_s, b.start_s) {
            (Some(sa), Some(sb)) => sb - sa,
            _ => 0.0,
        };
        let tolerance_s = tolerance([ta, tb]);
        let apart: Vec<usize> = (0..ta.len())
            .filter(|&i| (tb[i] + offset - ta[i]).abs() > tolerance_s)
            .collect();
        if let Some(&frame) = apart.first() {
            warnings.push(PairingWarning::Timing {
                frame,
                time_a_s: ta[frame],
                time_b_s: tb[frame] + offset,
                count: apart.len(),
                tolerance_s,
            });
        }
    }
    let pairs = (0..a.count())
        .map(|frame| FramePair {
            frame,
            time_s: times_a.or(times_b).map(|t| t[frame]),
        })
        .collect();
    Ok(Pairing {
        pairs,
        timed: times_a.is_some() && times_b.is_some(),
        warnings,
    })
}
