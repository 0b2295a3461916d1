//! Pixels in the page: decoding what the user drops, the working resolution, and geometry drawn
//! over the views (tip estimate, force arrows).

use hnet_twin::carm::CArm;
use hnet_twin::raster::GreyImage;
use hnet_twin::vec3::Vec3;

/// Side of the square images the page labels and exports, pixels (the paper's input size). The
/// model sees them resized to its own input size.
pub const WORK_SIZE: usize = 224;

/// Largest upload accepted, bytes.
pub const MAX_UPLOAD_BYTES: usize = 40 * 1024 * 1024;

/// Largest decoded image accepted, pixels per side.
pub const MAX_UPLOAD_SIDE: u32 = 8192;

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

/// Decodes a PNG or JPEG and resizes it to `size` x `size` RGB.
pub fn decode_to_rgb(file: &str, bytes: &[u8], size: usize) -> Result<Vec<u8>, ImageError> {
    Ok(resize_rgb(&decode(file, bytes)?, size))
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
    if width > MAX_UPLOAD_SIDE || height > MAX_UPLOAD_SIDE {
        return Err(error(format!(
            "the image is {width} x {height} pixels; the limit is {MAX_UPLOAD_SIDE} per side"
        )));
    }
    let mut reader = reader();
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_UPLOAD_SIDE);
    limits.max_image_height = Some(MAX_UPLOAD_SIDE);
    limits.max_alloc = Some(512 * 1024 * 1024);
    reader.limits(limits);
    reader.decode().map_err(undecodable)
}

/// `image` as `size` x `size` RGB bytes (triangle filter).
pub fn resize_rgb(image: &image::DynamicImage, size: usize) -> Vec<u8> {
    image
        .resize_exact(
            size as u32,
            size as u32,
            image::imageops::FilterType::Triangle,
        )
        .to_rgb8()
        .into_raw()
}

/// Resizes square RGB bytes from `from` to `to` pixels per side.
pub fn rescale_rgb(rgb: &[u8], from: usize, to: usize) -> Vec<u8> {
    if from == to {
        return rgb.to_vec();
    }
    let image = image::RgbImage::from_raw(from as u32, from as u32, rgb.to_vec())
        .expect("buffer of the stated size");
    image::imageops::resize(
        &image,
        to as u32,
        to as u32,
        image::imageops::FilterType::Triangle,
    )
    .into_raw()
}

/// Resizes a square mask of probabilities from `from` to `to` pixels per side (bilinear).
pub fn rescale_mask(mask: &[f32], from: usize, to: usize) -> Vec<f32> {
    if from == to {
        return mask.to_vec();
    }
    let image = GreyImage {
        width: from,
        height: from,
        data: mask.to_vec(),
    };
    image
        .crop_resampled(hnet_twin::raster::Rect([0.0, 0.0, 1.0, 1.0]), to, to)
        .data
}

/// Catheter label (0 or 255) of each pixel of a probability mask: 255 where `p >= 0.5`.
pub fn binarize(probabilities: &[f32]) -> Vec<u8> {
    probabilities
        .iter()
        .map(|&p| if p >= 0.5 { 255 } else { 0 })
        .collect()
}

/// The catheter's tip in a mask of `size` x `size` pixels (values `>= threshold` are catheter):
/// of the catheter pixels, the one farthest from where the catheter enters the image (its pixel
/// nearest to the border). `None` when the mask is empty. Anchors the force arrow when the 3D
/// geometry is unknown (uploaded pairs). Image coordinates, pixels.
pub fn estimate_tip<T: Copy + PartialOrd>(
    mask: &[T],
    size: usize,
    threshold: T,
) -> Option<[f64; 2]> {
    let pixels: Vec<(f64, f64)> = mask
        .iter()
        .enumerate()
        .filter(|(_, m)| **m >= threshold)
        .map(|(i, _)| ((i % size) as f64 + 0.5, (i / size) as f64 + 0.5))
        .collect();
    let border = |&(x, y): &(f64, f64)| x.min(y).min(size as f64 - x).min(size as f64 - y);
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
pub fn force_arrow(view: &CArm, start: [f64; 2], force_n: [f32; 3]) -> [[f64; 2]; 2] {
    let r = view.rotation();
    let f = Vec3::new(
        f64::from(force_n[0]),
        f64::from(force_n[1]),
        f64::from(force_n[2]),
    );
    [
        start,
        [
            start[0] + r.row(0).dot(f) * ARROW_PX_PER_NEWTON,
            start[1] + r.row(1).dot(f) * ARROW_PX_PER_NEWTON,
        ],
    ]
}

/// Magnitude of a force in newtons.
pub fn magnitude(force_n: [f32; 3]) -> f32 {
    force_n.iter().map(|f| f * f).sum::<f32>().sqrt()
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
        let rgb = decode_to_rgb("a.png", &png(300, 100), 32).unwrap();
        assert_eq!(rgb.len(), 32 * 32 * 3);
        assert_eq!(&rgb[..3], &[10, 200, 30]);

        let err = decode_to_rgb("notes.txt", b"hello, not an image", 32).unwrap_err();
        assert_eq!(err.file, "notes.txt");
        assert!(err.problem.contains("not an image"), "{err}");
        let err = decode_to_rgb("empty.png", b"", 32).unwrap_err();
        assert!(err.to_string().contains("empty.png: the file is empty"));
        let mut cut = png(64, 64);
        cut.truncate(cut.len() / 2);
        let err = decode_to_rgb("cut.png", &cut, 32).unwrap_err();
        assert!(err.problem.contains("cannot be decoded"), "{err}");
    }

    #[test]
    fn huge_images_are_refused_before_decoding() {
        let mut bytes = Vec::new();
        image::GrayImage::new(MAX_UPLOAD_SIDE + 1, 1)
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .unwrap();
        let err = decode_to_rgb("wide.png", &bytes, 32).unwrap_err();
        assert!(err.problem.contains("8193 x 1 pixels"), "{err}");
    }

    #[test]
    fn the_tip_is_the_catheter_end_away_from_the_border() {
        let size = 20;
        let mut mask = vec![0u8; size * size];
        // A horizontal catheter entering from the left edge, ending at x = 12.
        for x in 0..13 {
            mask[10 * size + x] = 255;
        }
        assert_eq!(estimate_tip(&mask, size, 128), Some([12.5, 10.5]));
        assert_eq!(estimate_tip(&[0.0f32; 4], 2, 0.5), None);
    }

    #[test]
    fn overlays_blend_by_coverage_and_opacity() {
        let rgb = [100u8, 100, 100, 100, 100, 100];
        let out = overlay(&rgb, [0.0, 1.0].into_iter(), [200, 0, 0], 0.5);
        assert_eq!(out, vec![100, 100, 100, 150, 50, 50]);
        assert_eq!(rgba(&out), vec![100, 100, 100, 255, 150, 50, 50, 255]);
        assert_eq!(binarize(&[0.2, 0.5, 0.9]), vec![0, 255, 255]);
    }
}
