//! A force trace over a cine: one tip-force estimate per frame pair, written as CSV
//! (`frame,time_s,fx_n,fy_n,fz_n,magnitude_n,fx_90_n,fy_90_n,fz_90_n,estimator,weights,note`:
//! frames
//! from 1, time in seconds after plane A's first frame, empty when the headers give no frame
//! time, forces in newtons in the twin's world frame to 0.1 mN, half the width of each axis's
//! 90 % interval (empty for weights that carry no calibration), the estimate it is (H-Net's
//! force head, or combined with the physics estimate), the weights file that made it, and for a
//! frame without a force why, its
//! force columns empty). The one format of `hnet trace` and the page's trace export; it holds
//! no header value besides the frame times, so no patient identifier.

use std::fmt::Write as _;

use hnet_twin::reconstruction::physics_force::TipForceEstimate;

/// The trace's header line.
pub const TRACE_COLUMNS: &str =
    "frame,time_s,fx_n,fy_n,fz_n,magnitude_n,fx_90_n,fy_90_n,fz_90_n,estimator,weights,note";

/// One frame pair's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct TracePoint {
    /// The frame, 0-based (written from 1).
    pub frame: usize,
    /// Time after plane A's first frame, seconds, when the headers give it.
    pub time_s: Option<f64>,
    /// The tip-force estimate, or why the frame has none.
    pub estimate: Result<TipForceEstimate, String>,
}

/// The CSV of `points` made with the weights file `weights` (its name), header line first, one
/// line per point in the given order.
pub fn trace_csv<'a>(points: impl IntoIterator<Item = &'a TracePoint>, weights: &str) -> String {
    // Commas and quotes cannot break a row: a text field is quoted, quotes doubled.
    let quoted = |text: &str| format!("\"{}\"", text.replace('"', "\"\""));
    let weights = quoted(weights);
    let mut csv = format!("{TRACE_COLUMNS}\n");
    for point in points {
        let time = point.time_s.map(|t| format!("{t:.4}")).unwrap_or_default();
        let frame = point.frame + 1;
        match &point.estimate {
            Ok(estimate) => {
                let f = estimate.force_n;
                let interval = estimate
                    .interval_90_n
                    .map(|h| format!("{:.4},{:.4},{:.4}", h[0], h[1], h[2]))
                    .unwrap_or_else(|| ",,".into());
                writeln!(
                    csv,
                    "{frame},{time},{:.4},{:.4},{:.4},{:.4},{interval},{},{weights},",
                    f[0],
                    f[1],
                    f[2],
                    f.magnitude(),
                    estimate.kind.name()
                )
            }
            Err(why) => writeln!(csv, "{frame},{time},,,,,,,,,{weights},{}", quoted(why)),
        }
        .expect("writing to a string");
    }
    csv
}

#[cfg(test)]
mod tests {
    use super::*;
    use hnet_twin::reconstruction::physics_force::EstimateKind;

    #[test]
    fn frames_count_from_one_and_missing_times_stay_empty() {
        let points = [
            TracePoint {
                frame: 0,
                time_s: Some(0.0667),
                estimate: Ok(TipForceEstimate {
                    force_n: hnet_units::TipForce::new(0.3, 0.0, -0.4),
                    interval_90_n: Some([0.05, 0.06, 0.07]),
                    kind: EstimateKind::Combined,
                }),
            },
            TracePoint {
                frame: 1,
                time_s: None,
                estimate: Ok(TipForceEstimate::uncalibrated(hnet_units::TipForce::ZERO)),
            },
            TracePoint {
                frame: 2,
                time_s: Some(0.1333),
                estimate: Err("view A: no catheter found, \"as said\"".into()),
            },
        ];
        assert_eq!(
            trace_csv(&points, "hnet-cpu.bpk"),
            "frame,time_s,fx_n,fy_n,fz_n,magnitude_n,fx_90_n,fy_90_n,fz_90_n,estimator,weights,note\n\
             1,0.0667,0.3000,0.0000,-0.4000,0.5000,0.0500,0.0600,0.0700,Combined,\"hnet-cpu.bpk\",\n\
             2,,0.0000,0.0000,0.0000,0.0000,,,,H-Net force head,\"hnet-cpu.bpk\",\n\
             3,0.1333,,,,,,,,,\"hnet-cpu.bpk\",\"view A: no catheter found, \"\"as said\"\"\"\n"
        );
    }
}
