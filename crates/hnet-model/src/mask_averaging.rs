//! Reading each view twice and averaging its masks (test-time augmentation, as nnU-Net reads
//! mirrored images): the network reads the view as given and its left-right mirror image, the
//! mirror's catheter probabilities are mirrored back, and the kept mask is the mean of the two.
//! The tip force is always the views as given's: the force head reads both views together, and a
//! pair of mirrored views is not the same scene mirrored in 3D.
//!
//! Only for networks whose training views were left-right symmetric: on the paper bench, whose
//! view A shows the catheter always bending towards the same side, the mirror image is a view
//! the network never saw, and view A's IoU fell from 0.96 to 0.34 (docs/results.md, "Reading each view
//! twice").
//!
//! Why the mirror image: it keeps the bottom edge, through which every training scene's catheter
//! entered, and every pixel's neighbours, and on an even width it keeps where the network's 2 x 2
//! pooling windows fall. Moves that change those windows do not qualify on twin X-rays: with a
//! view moved one column, the bundled network's catheter IoU fell from 0.95 to 0.68, and four
//! readings (each also moved one row down) gained nothing on the mirror's two
//! (docs/log/2026-12-07-reading-each-view-twice.md).
//!
//! Buffers are planar and row-major: `planes · height · width` values, a plane per channel (and
//! per image of a batch).

use alloc::vec::Vec;

use hnet_units::ImageSize;

pub use hnet_units::mask::MaskAveraging;

/// `planes` (planar, `planes · height · width` values) mirrored left to right: column `x` to
/// `width - 1 - x`. Its own inverse.
pub fn mirrored(planes: &[f32], size: ImageSize) -> Vec<f32> {
    let mut out = planes.to_vec();
    for row in out.chunks_exact_mut(size.width) {
        row.reverse();
    }
    out
}

/// The mean of `mask` (as read) and `mirror_mask` (read on the mirror image, not yet mirrored
/// back), written into `mask`.
pub fn average_with_mirror(mask: &mut [f32], mirror_mask: &[f32], size: ImageSize) {
    for (row, mirror_row) in mask
        .chunks_exact_mut(size.width)
        .zip(mirror_mask.chunks_exact(size.width))
    {
        for (p, m) in row.iter_mut().zip(mirror_row.iter().rev()) {
            *p = 0.5 * (*p + m);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    #[test]
    fn a_mirror_image_mirrors_back() {
        let size = ImageSize::new(3, 2);
        let planes: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let once = mirrored(&planes, size);
        assert_eq!(once[..6], [2.0, 1.0, 0.0, 5.0, 4.0, 3.0]);
        assert_eq!(mirrored(&once, size), planes);
        let mut mask = vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        average_with_mirror(&mut mask, &[0.0, 0.0, 1.0, 1.0, 0.0, 0.0], size);
        assert_eq!(mask, [1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let mut mask = vec![1.0; 6];
        average_with_mirror(&mut mask, &[0.0; 6], size);
        assert_eq!(mask, [0.5; 6]);
    }
}
