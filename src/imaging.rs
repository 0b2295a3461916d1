//! Pixels in the page: decoding what the user drops, the working resolution, and geometry drawn
//! over the views (tip estimate, force arrows).

use hnet_twin::dataset::resized;
use hnet_twin::simulator::carm::CArm;
use hnet_twin::simulator::raster::GreyImage;
use hnet_twin::vec3::Vec3;
use hnet_units::{ImageSize, MAX_IMAGE_SIDE, TipForce};

/// Size of the images the page labels and exports: 224×224 pixels (the paper's input size). The
/// model sees them resized to its own input size.
pub const WORK_SIZE: ImageSize = ImageSize::square(224);

/// Largest upload accepted, bytes.
pub const MAX_UPLOAD_BYTES: usize = 40 * 1024 * 1024;

/// Why an uploaded file cannot be used: the file, what is wrong, and the decoder's error when
/// the bytes could not be decoded.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {problem}")]
pub struct ImageError {
    /// The file's name.
    pub file: String,
    /// What is wrong.
    pub problem: String,
    /// The decoder's error.
    #[source]
    pub cause: Option<image::ImageError>,
}

/// Decodes a PNG or JPEG and resizes it to RGB of `size` pixels ([`resized`]).
pub fn decode_to_rgb(file: &str, bytes: &[u8], size: ImageSize) -> Result<Vec<u8>, ImageError> {
    let image = resized(decode(file, bytes)?, size);
    Ok(image.into_rgb8().into_raw())
}

/// Longest side a radiograph is kept at for the background composer, pixels.
pub const RADIOGRAPH_SIDE: u32 = 1024;

/// Decodes a chest radiograph (PNG or JPEG, bright = dense) as grey values in `[0, 1]`, scaled
/// down to at most [`RADIOGRAPH_SIDE`] pixels on its longer side.
pub fn decode_radiograph(file: &str, bytes: &[u8]) -> Result<GreyImage, ImageError> {
    let image = decode(file, bytes)?;
    let image = if image.width().max(image.height()) > RADIOGRAPH_SIDE {
        image.resize(
            RADIOGRAPH_SIDE,
            RADIOGRAPH_SIDE,
            image::imageops::FilterType::Triangle,
        )
    } else {
        image
    };
    let grey = image.to_luma8();
    Ok(GreyImage::from_u8(
        grey.width() as usize,
        grey.height() as usize,
        grey.as_raw(),
    ))
}

/// Decodes a PNG or JPEG upload within the size limits.
fn decode(file: &str, bytes: &[u8]) -> Result<image::DynamicImage, ImageError> {
    let error = |problem: String| ImageError {
        file: file.to_string(),
        problem,
        cause: None,
    };
    let undecodable = |e: image::ImageError| ImageError {
        cause: Some(e),
        ..error("cannot be decoded".into())
    };
    if bytes.is_empty() {
        return Err(error("the file is empty".into()));
    }
    if bytes.len() > MAX_UPLOAD_BYTES {
        return Err(error(format!(
            "the file is {} MB; the limit is {} MB",
            bytes.len() / (1024 * 1024),
            MAX_UPLOAD_BYTES / (1024 * 1024)
        )));
    }
    let format = image::guess_format(bytes)
        .map_err(|_| error("not an image (PNG or JPEG expected)".into()))?;
    if !matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
        return Err(error(format!(
            "{format:?} images are not supported; use PNG or JPEG"
        )));
    }
    let reader = || image::ImageReader::with_format(std::io::Cursor::new(bytes), format);
    let (width, height) = reader().into_dimensions().map_err(undecodable)?;
    let max_side = MAX_IMAGE_SIDE as u32;
    if width > max_side || height > max_side {
        return Err(error(format!(
            "the image is {width} x {height} pixels; the limit is {MAX_IMAGE_SIDE} per side"
        )));
    }
    let mut reader = reader();
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(max_side);
    limits.max_image_height = Some(max_side);
    limits.max_alloc = Some(512 * 1024 * 1024);
    reader.limits(limits);
    reader.decode().map_err(undecodable)
}

/// Resizes RGB bytes from `from` to `to` pixels ([`resized`]).
pub fn rescale_rgb(rgb: &[u8], from: ImageSize, to: ImageSize) -> Vec<u8> {
    if from == to {
        return rgb.to_vec();
    }
    let image = image::RgbImage::from_raw(from.width as u32, from.height as u32, rgb.to_vec())
        .expect("buffer of the stated size");
    resized(image.into(), to).into_rgb8().into_raw()
}

/// Resizes a mask of probabilities from `from` to `to` pixels (bilinear).
pub fn rescale_mask(mask: &[f32], from: ImageSize, to: ImageSize) -> Vec<f32> {
    if from == to {
        return mask.to_vec();
    }
    let image = GreyImage {
        width: from.width,
        height: from.height,
        data: mask.to_vec(),
    };
    image
        .crop_resampled(
            hnet_twin::simulator::raster::Rect([0.0, 0.0, 1.0, 1.0]),
            to.width,
            to.height,
        )
        .data
}

/// The catheter's tip in a mask of `size` pixels (values `>= threshold` are catheter:
/// [`hnet_units::mask::LABEL_THRESHOLD`] for 8-bit labels, [`hnet_units::mask::MASK_THRESHOLD`]
/// for probabilities):
/// of the catheter pixels, the one farthest from where the catheter enters the image (its pixel
/// nearest to the border). `None` when the mask is empty. Anchors the force arrow when the 3D
/// geometry is unknown (uploaded pairs). Image coordinates, pixels.
pub fn estimate_tip<T: Copy + PartialOrd>(
    mask: &[T],
    size: ImageSize,
    threshold: T,
) -> Option<[f64; 2]> {
    let pixels: Vec<(f64, f64)> = mask
        .iter()
        .enumerate()
        .filter(|(_, m)| **m >= threshold)
        .map(|(i, _)| ((i % size.width) as f64 + 0.5, (i / size.width) as f64 + 0.5))
        .collect();
    let (width, height) = (size.width as f64, size.height as f64);
    let border = |&(x, y): &(f64, f64)| x.min(y).min(width - x).min(height - y);
    let entry = pixels
        .iter()
        .min_by(|a, b| border(a).total_cmp(&border(b)))?;
    let tip = pixels.iter().max_by(|a, b| {
        let d = |p: &(f64, f64)| (p.0 - entry.0).powi(2) + (p.1 - entry.1).powi(2);
        d(a).total_cmp(&d(b))
    })?;
    Some([tip.0, tip.1])
}

/// Where a 3D point (mm, world frame) appears in `view`, image coordinates in pixels.
pub fn project(view: &CArm, point_mm: [f64; 3]) -> [f64; 2] {
    let p = view.project(Vec3(point_mm));
    [p.u, p.v]
}

/// Pixels per newton of the drawn force arrows at the working size.
pub const ARROW_PX_PER_NEWTON: f64 = 180.0;

/// The 2D arrow of `force_n` (newtons, world frame) in `view`, starting at `start` (image
/// coordinates at [`WORK_SIZE`]): the force's components along the view's image axes.
pub fn force_arrow(view: &CArm, start: [f64; 2], force_n: TipForce) -> [[f64; 2]; 2] {
    let r = view.rotation();
    let f = Vec3::from(force_n);
    [
        start,
        [
            start[0] + r.row(0).dot(f) * ARROW_PX_PER_NEWTON,
            start[1] + r.row(1).dot(f) * ARROW_PX_PER_NEWTON,
        ],
    ]
}

/// An RGB image with a coloured overlay: `coverage` (one value in `[0, 1]` per pixel) blended
/// in `colour` at `opacity`. Overlays chain: the result is RGB again.
pub fn overlay(
    rgb: &[u8],
    coverage: impl Iterator<Item = f32>,
    colour: [u8; 3],
    opacity: f32,
) -> Vec<u8> {
    rgb.chunks_exact(3)
        .zip(coverage)
        .flat_map(|(p, c)| {
            let a = c.clamp(0.0, 1.0) * opacity.clamp(0.0, 1.0);
            let mix = |v: u8, k: u8| (f32::from(v) * (1.0 - a) + f32::from(k) * a).round() as u8;
            [
                mix(p[0], colour[0]),
                mix(p[1], colour[1]),
                mix(p[2], colour[2]),
            ]
        })
        .collect()
}

/// RGBA pixels of an RGB image, opaque (for a canvas).
pub fn rgba(rgb: &[u8]) -> Vec<u8> {
    rgb.chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect()
}

// Native tests (`cargo test`); the browser tests are in tests/web.rs.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    fn png(width: u32, height: u32) -> Vec<u8> {
        let mut bytes = Vec::new();
        image::RgbImage::from_pixel(width, height, image::Rgb([10, 200, 30]))
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .unwrap();
        bytes
    }

    #[test]
    fn uploads_are_decoded_and_resized_or_named_in_the_error() {
        let rgb = decode_to_rgb("a.png", &png(300, 100), ImageSize::square(32)).unwrap();
        assert_eq!(rgb.len(), 32 * 32 * 3);
        assert_eq!(&rgb[..3], &[10, 200, 30]);

        let err =
            decode_to_rgb("notes.txt", b"hello, not an image", ImageSize::square(32)).unwrap_err();
        assert_eq!(err.file, "notes.txt");
        assert!(err.problem.contains("not an image"), "{err}");
        let err = decode_to_rgb("empty.png", b"", ImageSize::square(32)).unwrap_err();
        assert!(err.to_string().contains("empty.png: the file is empty"));
        let mut cut = png(64, 64);
        cut.truncate(cut.len() / 2);
        let err = decode_to_rgb("cut.png", &cut, ImageSize::square(32)).unwrap_err();
        assert!(err.problem.contains("cannot be decoded"), "{err}");
    }

    #[test]
    fn huge_images_are_refused_before_decoding() {
        let mut bytes = Vec::new();
        image::GrayImage::new(MAX_IMAGE_SIDE as u32 + 1, 1)
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .unwrap();
        let err = decode_to_rgb("wide.png", &bytes, ImageSize::square(32)).unwrap_err();
        assert!(err.problem.contains("8193 x 1 pixels"), "{err}");
    }

    #[test]
    fn the_tip_is_the_catheter_end_away_from_the_border() {
        let size = ImageSize::square(20);
        let mut mask = vec![0u8; size.pixels()];
        // A horizontal catheter entering from the left edge, ending at x = 12.
        for x in 0..13 {
            mask[10 * size.width + x] = 255;
        }
        assert_eq!(
            estimate_tip(&mask, size, hnet_units::mask::LABEL_THRESHOLD),
            Some([12.5, 10.5])
        );
        assert_eq!(
            estimate_tip(
                &[0.0f32; 4],
                ImageSize::square(2),
                hnet_units::mask::MASK_THRESHOLD
            ),
            None
        );
    }

    #[test]
    fn overlays_blend_by_coverage_and_opacity() {
        let rgb = [100u8, 100, 100, 100, 100, 100];
        let out = overlay(&rgb, [0.0, 1.0].into_iter(), [200, 0, 0], 0.5);
        assert_eq!(out, vec![100, 100, 100, 150, 50, 50]);
        assert_eq!(rgba(&out), vec![100, 100, 100, 255, 150, 50, 50, 255]);
    }
}

// Property tests (issue #13, docs/reliability.md): any upload is decoded within the size limits
// or refused with an error, never a panic or an allocation beyond the limits.
#[cfg(all(test, not(target_arch = "wasm32")))]
pub(crate) mod properties {
    use super::*;
    pub(crate) use hnet_mutations::cases;
    use hnet_mutations::{edits, mutate};
    use proptest::prelude::*;

    /// An image whose header claims a huge size fails visibly (see `hnet_mutations`); the
    /// decoder's own limit is 512 MiB.
    #[global_allocator]
    static ALLOCATOR: hnet_mutations::CappedAllocator = hnet_mutations::CappedAllocator;

    /// A small test image in `format`.
    fn encoded(format: image::ImageFormat, grey: bool) -> Vec<u8> {
        let rgb = image::RgbImage::from_fn(16, 12, |x, y| {
            image::Rgb([(x * 15) as u8, (y * 20) as u8, ((x + y) * 7) as u8])
        });
        let image = if grey {
            image::DynamicImage::ImageLuma8(image::DynamicImage::ImageRgb8(rgb).to_luma8())
        } else {
            image::DynamicImage::ImageRgb8(rgb)
        };
        let mut bytes = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut bytes), format)
            .unwrap();
        bytes
    }

    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
            }
        }
        !crc
    }

    /// A PNG whose header (IHDR) claims `width` x `height`, `depth` bits and `colour` type, with
    /// a correct checksum so that the decoder believes it; the pixel data stays the original's.
    fn png_claiming(width: u32, height: u32, depth: u8, colour: u8) -> Vec<u8> {
        let mut png = encoded(image::ImageFormat::Png, false);
        // Signature (8), IHDR length (4) and type (4), then the 13 bytes of IHDR data.
        png[16..20].copy_from_slice(&width.to_be_bytes());
        png[20..24].copy_from_slice(&height.to_be_bytes());
        png[24] = depth;
        png[25] = colour;
        let crc = crc32(&png[12..29]);
        png[29..33].copy_from_slice(&crc.to_be_bytes());
        png
    }

    /// A JPEG whose frame header (SOF0) claims `width` x `height`.
    fn jpeg_claiming(width: u16, height: u16) -> Vec<u8> {
        let mut jpeg = encoded(image::ImageFormat::Jpeg, false);
        let sof = jpeg
            .windows(2)
            .position(|w| w == [0xFF, 0xC0])
            .expect("a baseline JPEG");
        // Marker (2), length (2), precision (1), then height and width.
        jpeg[sof + 5..sof + 7].copy_from_slice(&height.to_be_bytes());
        jpeg[sof + 7..sof + 9].copy_from_slice(&width.to_be_bytes());
        jpeg
    }

    /// Decodes `bytes` both ways the page does; a result must respect the limits.
    fn decode_both_ways(bytes: &[u8]) -> Result<(), TestCaseError> {
        if let Ok(rgb) = decode_to_rgb("p.png", bytes, ImageSize::square(32)) {
            prop_assert_eq!(rgb.len(), 32 * 32 * 3);
        }
        if let Ok(grey) = decode_radiograph("p.png", bytes) {
            prop_assert!(grey.width <= RADIOGRAPH_SIDE as usize);
            prop_assert!(grey.height <= RADIOGRAPH_SIDE as usize);
            prop_assert_eq!(grey.data.len(), grey.width * grey.height);
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(cases(256))]

        #[test]
        fn any_bytes_are_an_image_or_an_error(
            head in prop_oneof![
                Just(&b""[..]),
                Just(&b"\x89PNG\r\n\x1a\n"[..]),
                Just(&[0xFF, 0xD8, 0xFF][..]),
            ],
            bytes in proptest::collection::vec(any::<u8>(), 0..512),
        ) {
            let bytes = [head, &bytes].concat();
            decode_both_ways(&bytes)?;
        }

        #[test]
        fn a_mutated_png_or_jpeg_is_an_image_or_an_error(
            jpeg in any::<bool>(),
            grey in any::<bool>(),
            edits in edits(),
        ) {
            let format = if jpeg { image::ImageFormat::Jpeg } else { image::ImageFormat::Png };
            decode_both_ways(&mutate(encoded(format, grey), &edits))?;
        }
    }

    proptest! {
        // A claimed size within the limit may decode a large (mostly empty) image: fewer cases.
        #![proptest_config(cases(48))]

        #[test]
        fn a_png_claiming_any_size_is_refused_or_decoded_within_the_limits(
            width in prop_oneof![1u32..64, 1u32..=MAX_IMAGE_SIDE as u32, any::<u32>()],
            height in prop_oneof![1u32..64, 1u32..=MAX_IMAGE_SIDE as u32, any::<u32>()],
            depth in prop_oneof![Just(8u8), Just(16u8), any::<u8>()],
            colour in prop_oneof![Just(2u8), Just(6u8), any::<u8>()],
        ) {
            let png = png_claiming(width, height, depth, colour);
            let result = decode_to_rgb("claims.png", &png, ImageSize::square(32));
            if width > MAX_IMAGE_SIDE as u32 || height > MAX_IMAGE_SIDE as u32 {
                let err = result.unwrap_err();
                prop_assert!(err.problem.contains("limit") || err.problem.contains("decoded"), "{}", err);
            }
            decode_both_ways(&png)?;
        }

        #[test]
        fn a_jpeg_claiming_any_size_is_refused_or_decoded_within_the_limits(
            width in prop_oneof![1u16..64, any::<u16>()],
            height in prop_oneof![1u16..64, any::<u16>()],
        ) {
            let jpeg = jpeg_claiming(width, height);
            let result = decode_to_rgb("claims.jpg", &jpeg, ImageSize::square(32));
            if u32::from(width) > MAX_IMAGE_SIDE as u32 || u32::from(height) > MAX_IMAGE_SIDE as u32 {
                prop_assert!(result.is_err());
            }
            decode_both_ways(&jpeg)?;
        }
    }

    #[test]
    fn uploads_over_the_byte_limit_are_refused_before_decoding() {
        let mut bytes = encoded(image::ImageFormat::Png, false);
        bytes.resize(MAX_UPLOAD_BYTES + 1, 0);
        let err = decode_to_rgb("big.png", &bytes, ImageSize::square(32)).unwrap_err();
        assert!(err.problem.contains("the limit is 40 MB"), "{err}");
    }
}
