//! When each frame was taken: Frame Time (0018,1063) or Frame Time Vector (0018,1065), both in
//! milliseconds, and Acquisition DateTime (0008,002A) for the start of the run.

use dicom_dictionary_std::tags;

use crate::attributes::{DicomObject, numbers, text};
use crate::error::DicomError;

/// The timing of one file's frames.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTiming {
    /// Each frame's time after the file's first frame, seconds; `None` when the header gives no
    /// frame time.
    pub frame_times_s: Option<Vec<f64>>,
    /// Acquisition DateTime, seconds since 1970-01-01 (the UTC offset ignored), when present.
    pub start_s: Option<f64>,
}

impl FrameTiming {
    /// Reads the timing of `object`'s `frames` frames (`file` names it in errors). A Frame Time
    /// Vector of another length than the frames is ignored in favour of Frame Time.
    pub fn read(object: &DicomObject, file: &str, frames: usize) -> Result<Self, DicomError> {
        let vector = numbers(object, file, tags::FRAME_TIME_VECTOR, "FrameTimeVector")?
            .filter(|v| v.len() == frames && v.iter().all(|t| t.is_finite() && *t >= 0.0));
        let frame_time = numbers(object, file, tags::FRAME_TIME, "FrameTime")?
            .and_then(|v| v.first().copied())
            .filter(|t| t.is_finite() && *t > 0.0);
        let frame_times_s = match (vector, frame_time) {
            (Some(increments_ms), _) => Some(
                increments_ms
                    .iter()
                    .enumerate()
                    .scan(0.0, |t, (i, dt)| {
                        // The first value is the time before the first frame: counted as zero.
                        if i > 0 {
                            *t += dt / 1000.0;
                        }
                        Some(*t)
                    })
                    .collect(),
            ),
            (None, Some(ms)) => Some((0..frames).map(|i| i as f64 * ms / 1000.0).collect()),
            (None, None) => None,
        };
        let start_s = text(object, tags::ACQUISITION_DATE_TIME)
            .as_deref()
            .and_then(parse_date_time);
        Ok(Self {
            frame_times_s,
            start_s,
        })
    }
}

/// A DICOM DT value (`YYYYMMDDHHMMSS.FFFFFF`, later parts optional, a `&ZZXX` offset ignored) as
/// seconds since 1970-01-01.
pub fn parse_date_time(value: &str) -> Option<f64> {
    let value = value.split(['+', '-']).next()?.trim();
    let (whole, fraction) = value.split_once('.').unwrap_or((value, ""));
    if whole.len() < 8 || !whole.bytes().all(|b| b.is_ascii_digit()) || whole.len() % 2 != 0 {
        return None;
    }
    let field = |from: usize, to: usize| -> Option<i64> {
        whole.get(from..to).map_or(Some(0), |s| s.parse().ok())
    };
    let (year, month, day) = (field(0, 4)?, field(4, 6)?, field(6, 8)?);
    let (hour, minute, second) = (field(8, 10)?, field(10, 12)?, field(12, 14)?);
    if !(1..=12).contains(&month) || !(1..=31).contains(&day) || hour > 23 || minute > 59 {
        return None;
    }
    let fraction: f64 = if fraction.is_empty() {
        0.0
    } else {
        format!("0.{fraction}").parse().ok()?
    };
    let days = days_from_civil(year, month, day);
    Some((days * 86_400 + hour * 3600 + minute * 60 + second) as f64 + fraction)
}

/// Days from 1970-01-01 to a proleptic Gregorian date (Howard Hinnant's algorithm).
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let year = if month <= 2 { year - 1 } else { year };
    let era = year.div_euclid(400);
    let year_of_era = year - era * 400;
    let month_index = (month + 9) % 12;
    let day_of_year = (153 * month_index + 2) / 5 + day - 1;
    let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
    era * 146_097 + day_of_era - 719_468
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn date_times_are_seconds_since_1970() {
        assert_eq!(parse_date_time("19700101"), Some(0.0));
        assert_eq!(parse_date_time("19700102000001.5"), Some(86_401.5));
        assert_eq!(
            parse_date_time("20240229120000.25+0100"),
            Some(1_709_208_000.25)
        );
        assert_eq!(parse_date_time("2024"), None);
        assert_eq!(parse_date_time("20241301"), None);
    }
}
