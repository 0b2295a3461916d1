//! A force trace over a cine: one tip-force estimate per frame pair, written as CSV
//! (`frame,time_s,fx_n,fy_n,fz_n,magnitude_n`: frames from 1, time in seconds after plane A's
//! first frame, empty when the headers give no frame time, forces in newtons in the twin's world
//! frame). The one format of `hnet trace` and the page's trace export; it holds no header value
//! besides the frame times, so no patient identifier.

use std::fmt::Write as _;

use hnet_units::force_magnitude;

/// The trace's header line.
pub const TRACE_COLUMNS: &str = "frame,time_s,fx_n,fy_n,fz_n,magnitude_n";

/// One frame pair's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TracePoint {
    /// The frame, 0-based (written from 1).
    pub frame: usize,
    /// Time after plane A's first frame, seconds, when the headers give it.
    pub time_s: Option<f64>,
    /// Tip force `(Fx, Fy, Fz)`, newtons.
    pub force_n: [f32; 3],
}

/// The CSV of `points`, header line first, one line per point in the given order.
pub fn trace_csv<'a>(points: impl IntoIterator<Item = &'a TracePoint>) -> String {
    let mut csv = format!("{TRACE_COLUMNS}\n");
    for point in points {
        let f = point.force_n;
        let time = point.time_s.map(|t| format!("{t:.4}")).unwrap_or_default();
        writeln!(
            csv,
            "{},{time},{},{},{},{}",
            point.frame + 1,
            f[0],
            f[1],
            f[2],
            force_magnitude(f)
        )
        .expect("writing to a string");
    }
    csv
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_count_from_one_and_missing_times_stay_empty() {
        let points = [
            TracePoint {
                frame: 0,
                time_s: Some(0.0667),
                force_n: [0.3, 0.0, -0.4],
            },
            TracePoint {
                frame: 1,
                time_s: None,
                force_n: [0.0; 3],
            },
        ];
        assert_eq!(
            trace_csv(&points),
            "frame,time_s,fx_n,fy_n,fz_n,magnitude_n\n1,0.0667,0.3,0,-0.4,0.5\n2,,0,0,0,0\n"
        );
    }
}
