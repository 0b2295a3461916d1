//! The sizes and units that H-Net Studio's network (`hnet-model`), digital twin (`hnet-twin`),
//! DICOM reader, command-line tool and page all speak of, defined once so that no caller has to
//! remember an index order or rewrite a formula; and [`with_causes`], how an error is worded
//! with its causes.
//!
//! [`ImageSize`] names its fields: `width` (pixels along `u`, a row's length) and `height`
//! (pixels along `v`, the number of rows). Tensors are `[batch, channels, height, width]` and
//! pixel buffers are row-major, `height` rows of `width` pixels.
//!
//! Files store a size as `{"width": W, "height": H}`. Files written before this type existed
//! stored bare arrays, in two orders: the network's settings `[height, width]` (the tensor
//! order) and the twin's `[width, height]`. [`ImageSize`]'s own `Deserialize` reads the object,
//! and an array as `[height, width]`; fields that held `[width, height]` read old files with
//! `#[serde(deserialize_with = "hnet_units::width_height_or_named")]`, and fields that held a
//! square's bare side with [`side_or_named`].
//!
//! [`TipForce`] is the tip force in newtons. [`mask`] holds the mask threshold: which pixels of a mask are catheter; [`turn`] the quarter
//! turns of a square image's pixels.
use core::fmt;

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

mod force;
pub mod mask;
pub mod turn;

pub use force::TipForce;

/// The largest image side accepted, pixels: the page's uploads, and the CLI's training image
/// size (every pair is resized to it, so a larger one would only exhaust memory).
pub const MAX_IMAGE_SIDE: usize = 8192;

/// `error`'s message followed by each of its causes, `: `-separated (as `hnet` prints them), so
/// that what a library kept (a decoder's or a device's own account) reaches the reader: the one
/// wording of the page, its WebGPU worker and their tests.
pub fn with_causes(error: &dyn core::error::Error) -> String {
    let mut text = error.to_string();
    let mut cause = error.source();
    while let Some(e) = cause {
        let message = e.to_string();
        // A wrapper that repeats its cause's words adds nothing.
        if !text.ends_with(&message) {
            text.push_str(": ");
            text.push_str(&message);
        }
        cause = e.source();
    }
    text
}

/// One of the two simultaneous views of a biplane pair: what the page labels, the network reads
/// (each through its segmentation branch) and the twin renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum View {
    /// View A (the frontal view of the default biplane).
    A,
    /// View B (the lateral view).
    B,
}

impl View {
    /// Both views, A first.
    pub const BOTH: [View; 2] = [View::A, View::B];

    /// `"A"` or `"B"`.
    pub fn letter(self) -> &'static str {
        match self {
            View::A => "A",
            View::B => "B",
        }
    }

    /// 0 for view A, 1 for view B: the view's place in a pair's arrays.
    pub fn index(self) -> usize {
        match self {
            View::A => 0,
            View::B => 1,
        }
    }
}

/// The size of an image, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct ImageSize {
    /// Pixels per row (along `u`).
    pub width: usize,
    /// Rows (along `v`).
    pub height: usize,
}

impl ImageSize {
    /// A size of `width` x `height` pixels.
    pub const fn new(width: usize, height: usize) -> Self {
        Self { width, height }
    }

    /// A square of `side` x `side` pixels.
    pub const fn square(side: usize) -> Self {
        Self::new(side, side)
    }

    /// Pixels in the image (`width · height`).
    pub const fn pixels(self) -> usize {
        self.width * self.height
    }

    /// Whether width and height are equal.
    pub const fn is_square(self) -> bool {
        self.width == self.height
    }

    /// `[height, width]`: the order of a tensor's last two dimensions.
    pub const fn height_width(self) -> [usize; 2] {
        [self.height, self.width]
    }

    /// The size of a tensor whose last two dimensions are `[.., height, width]`.
    pub fn of_dims(dims: &[usize]) -> Option<Self> {
        match dims {
            [.., height, width] => Some(Self::new(*width, *height)),
            _ => None,
        }
    }
}

/// `W×H`, the way image sizes are written in the user interface and in messages.
impl fmt::Display for ImageSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}×{}", self.width, self.height)
    }
}

/// What else than `{"width": W, "height": H}` a file written before [`ImageSize`] existed may
/// hold: a bare two-number array in one of two orders, or a square's bare side.
#[derive(Clone, Copy)]
enum OldSpelling {
    HeightWidth,
    WidthHeight,
    Side,
}

/// A key of `{"width": W, "height": H}`.
#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum Field {
    Width,
    Height,
}

struct SizeVisitor(OldSpelling);

impl<'de> Visitor<'de> for SizeVisitor {
    type Value = ImageSize;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an image size {\"width\": W, \"height\": H} in pixels")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<ImageSize, A::Error> {
        let (mut width, mut height) = (None, None);
        while let Some(field) = map.next_key::<Field>()? {
            match field {
                Field::Width => width = Some(map.next_value()?),
                Field::Height => height = Some(map.next_value()?),
            }
        }
        Ok(ImageSize {
            width: width.ok_or_else(|| de::Error::missing_field("width"))?,
            height: height.ok_or_else(|| de::Error::missing_field("height"))?,
        })
    }

    fn visit_u64<E: de::Error>(self, side: u64) -> Result<ImageSize, E> {
        match self.0 {
            OldSpelling::Side => usize::try_from(side)
                .map(ImageSize::square)
                .map_err(|_| E::invalid_value(de::Unexpected::Unsigned(side), &self)),
            _ => Err(E::invalid_type(de::Unexpected::Unsigned(side), &self)),
        }
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<ImageSize, A::Error> {
        if let OldSpelling::Side = self.0 {
            return Err(de::Error::invalid_type(de::Unexpected::Seq, &self));
        }
        let first: usize = seq
            .next_element()?
            .ok_or_else(|| de::Error::invalid_length(0, &self))?;
        let second: usize = seq
            .next_element()?
            .ok_or_else(|| de::Error::invalid_length(1, &self))?;
        if seq.next_element::<de::IgnoredAny>()?.is_some() {
            return Err(de::Error::invalid_length(3, &self));
        }
        Ok(match self.0 {
            OldSpelling::HeightWidth => ImageSize::new(second, first),
            OldSpelling::WidthHeight | OldSpelling::Side => ImageSize::new(first, second),
        })
    }
}

impl<'de> Deserialize<'de> for ImageSize {
    /// Reads `{"width": W, "height": H}`, or a bare `[height, width]` array (the network's
    /// settings before this type existed).
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(SizeVisitor(OldSpelling::HeightWidth))
    }
}

/// Reads `{"width": W, "height": H}`, or a bare `[width, height]` array (the twin's datasets
/// and C-arm settings before [`ImageSize`] existed). For `#[serde(deserialize_with = ..)]`.
pub fn width_height_or_named<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<ImageSize, D::Error> {
    deserializer.deserialize_any(SizeVisitor(OldSpelling::WidthHeight))
}

/// Reads `{"width": W, "height": H}`, or a bare number: the side of a square, pixels (the twin's
/// `image_size` before [`ImageSize`] existed). For `#[serde(deserialize_with = ..)]`.
pub fn side_or_named<'de, D: Deserializer<'de>>(deserializer: D) -> Result<ImageSize, D::Error> {
    deserializer.deserialize_any(SizeVisitor(OldSpelling::Side))
}

#[cfg(test)]
mod tests {
    extern crate std;

    use std::string::ToString;

    use super::*;

    #[test]
    fn causes_follow_the_message_and_a_repeated_cause_is_said_once() {
        #[derive(Debug)]
        struct Error(&'static str, Option<&'static Error>);
        impl fmt::Display for Error {
            fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(self.0)
            }
        }
        impl core::error::Error for Error {
            fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
                self.1.map(|e| e as _)
            }
        }
        static ROOT: Error = Error("unexpected end of file", None);
        static SAME: Error = Error("scan.png: unexpected end of file", Some(&ROOT));
        assert_eq!(
            with_causes(&Error("scan.png: cannot be decoded", Some(&ROOT))),
            "scan.png: cannot be decoded: unexpected end of file"
        );
        assert_eq!(with_causes(&SAME), "scan.png: unexpected end of file");
    }

    #[test]
    fn named_fields_round_trip_and_old_arrays_keep_their_meaning() {
        let size = ImageSize::new(320, 240);
        let json = serde_json::to_string(&size).unwrap();
        assert_eq!(json, r#"{"width":320,"height":240}"#);
        assert_eq!(serde_json::from_str::<ImageSize>(&json).unwrap(), size);
        // The network's old settings were [height, width].
        assert_eq!(
            serde_json::from_str::<ImageSize>("[240, 320]").unwrap(),
            size
        );
        // The twin's old files were [width, height].
        let mut de = serde_json::Deserializer::from_str("[320, 240]");
        assert_eq!(width_height_or_named(&mut de).unwrap(), size);
        let mut de = serde_json::Deserializer::from_str(&json);
        assert_eq!(width_height_or_named(&mut de).unwrap(), size);
        for bad in [
            "[1]",
            "[1, 2, 3]",
            r#"{"width": 3}"#,
            r#"{"w": 3, "h": 2}"#,
            "7",
        ] {
            assert!(serde_json::from_str::<ImageSize>(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_bare_side_reads_as_a_square_where_files_held_one() {
        let read = |json: &str| side_or_named(&mut serde_json::Deserializer::from_str(json));
        assert_eq!(read("224").unwrap(), ImageSize::square(224));
        let size = ImageSize::new(320, 240);
        assert_eq!(read(&serde_json::to_string(&size).unwrap()).unwrap(), size);
        for bad in [
            "-1",
            "2.5",
            "[320, 240]",
            r#"{"width": 3}"#,
            "\"224\"",
            "null",
        ] {
            assert!(read(bad).is_err(), "{bad}");
        }
        // Only this reader takes a bare side.
        assert!(serde_json::from_str::<ImageSize>("224").is_err());
        let mut de = serde_json::Deserializer::from_str("224");
        assert!(width_height_or_named(&mut de).is_err());
    }

    #[test]
    fn tensor_order_and_display() {
        let size = ImageSize::new(320, 240);
        assert_eq!(size.height_width(), [240, 320]);
        assert_eq!(ImageSize::of_dims(&[8, 3, 240, 320]), Some(size));
        assert_eq!(size.pixels(), 76_800);
        assert_eq!(size.to_string(), "320×240");
        assert!(!size.is_square() && ImageSize::square(64).is_square());
    }

    // Property tests (issue #13, docs/reliability.md).
    mod properties {
        use std::format;
        use std::string::String;
        use std::vec::Vec;

        use proptest::prelude::*;

        use super::*;

        proptest! {
            #![proptest_config(hnet_mutations::cases(256))]

            #[test]
            fn sizes_round_trip_exactly_in_every_reader(width in any::<usize>(), height in any::<usize>()) {
                let size = ImageSize::new(width, height);
                let json = serde_json::to_string(&size).unwrap();
                prop_assert_eq!(serde_json::from_str::<ImageSize>(&json).unwrap(), size);
                let mut de = serde_json::Deserializer::from_str(&json);
                prop_assert_eq!(width_height_or_named(&mut de).unwrap(), size);
                // The old arrays, each in its own order.
                let array = format!("[{height}, {width}]");
                prop_assert_eq!(serde_json::from_str::<ImageSize>(&array).unwrap(), size);
                let array = format!("[{width}, {height}]");
                let mut de = serde_json::Deserializer::from_str(&array);
                prop_assert_eq!(width_height_or_named(&mut de).unwrap(), size);
                let mut de = serde_json::Deserializer::from_str(&json);
                prop_assert_eq!(side_or_named(&mut de).unwrap(), size);
                // The old bare side, a square.
                let side = format!("{width}");
                let mut de = serde_json::Deserializer::from_str(&side);
                prop_assert_eq!(side_or_named(&mut de).unwrap(), ImageSize::square(width));
            }

            #[test]
            fn any_text_is_a_size_or_an_error(text in "\\PC{0,40}", bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
                let _ = serde_json::from_str::<ImageSize>(&text);
                let _ = serde_json::from_slice::<ImageSize>(&bytes);
                let mut de = serde_json::Deserializer::from_str(&text);
                let _ = width_height_or_named(&mut de);
                let mut de = serde_json::Deserializer::from_str(&text);
                let _ = side_or_named(&mut de);
            }

            #[test]
            fn json_shaped_like_a_size_is_a_size_or_an_error(
                keys in proptest::collection::vec(prop_oneof!["width", "height", "w", "\\PC{0,4}"], 0..4),
                values in proptest::collection::vec(prop_oneof![
                    any::<u64>().prop_map(|v| format!("{v}")),
                    any::<i64>().prop_map(|v| format!("{v}")),
                    any::<f64>().prop_map(|v| format!("{v:?}")),
                    Just(String::from("null")),
                    Just(String::from("18446744073709551616")),
                    Just(String::from("[1, 2]")),
                ], 0..4),
                array in any::<bool>(),
            ) {
                let json = if array {
                    format!("[{}]", values.join(", "))
                } else {
                    let fields: Vec<String> = keys
                        .iter()
                        .zip(values.iter().chain(core::iter::repeat(&String::from("1"))))
                        .map(|(k, v)| format!("{}: {v}", serde_json::to_string(k).unwrap()))
                        .collect();
                    format!("{{{}}}", fields.join(", "))
                };
                if let Ok(size) = serde_json::from_str::<ImageSize>(&json) {
                    // Whatever parses writes back as the same size.
                    let back = serde_json::to_string(&size).unwrap();
                    prop_assert_eq!(serde_json::from_str::<ImageSize>(&back).unwrap(), size);
                }
            }
        }
    }
}
