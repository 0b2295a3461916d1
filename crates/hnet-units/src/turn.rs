//! Quarter turns of a square image's pixels: the one turn of the network's catheter-entry
//! reading (`hnet_model::catheter_entry`, on the page and in `hnet eval`) and of the dataset's
//! square symmetries (`hnet_twin::dataset::SquareSymmetry`, `hnet eval --turn-views` and
//! training's augmentation). Exact on the pixel grid (no resampling).

use core::fmt;

use crate::ImageSize;

/// An image to be turned is not a square of the expected size.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TurnError {
    /// The image size.
    pub size: ImageSize,
    /// Values per pixel.
    pub channels: usize,
    /// Values found.
    pub found: usize,
}

impl fmt::Display for TurnError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cannot turn a view of {} with {} values ({} per pixel): only square images of the \
             network's input size can be turned",
            self.size, self.found, self.channels
        )
    }
}

impl core::error::Error for TurnError {}

/// `values`, a square image of `size` with `channels` interleaved values per pixel (row-major),
/// turned clockwise by `quarter_turns` (counted modulo 4). A clockwise turn takes the right edge
/// to the bottom and the top-left pixel to the top-right corner.
pub fn turn_clockwise<T: Copy>(
    values: &[T],
    size: ImageSize,
    channels: usize,
    quarter_turns: u8,
) -> Result<Vec<T>, TurnError> {
    let side = size.width;
    if size.height != side || values.len() != side * side * channels {
        return Err(TurnError {
            size,
            channels,
            found: values.len(),
        });
    }
    let turns = quarter_turns % 4;
    if turns == 0 {
        return Ok(values.to_vec());
    }
    let last = side.saturating_sub(1);
    let mut turned = Vec::with_capacity(values.len());
    for row in 0..side {
        for col in 0..side {
            // The source pixel of (row, col) after the turn.
            let (src_row, src_col) = match turns {
                1 => (last - col, row),
                2 => (last - row, last - col),
                _ => (col, last - row),
            };
            let at = (src_row * side + src_col) * channels;
            turned.extend_from_slice(&values[at..at + channels]);
        }
    }
    Ok(turned)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: ImageSize = ImageSize::square(3);

    #[test]
    fn a_clockwise_turn_takes_the_right_edge_to_the_bottom() {
        // 0 1 2 / 3 4 5 / 6 7 8 turned clockwise: 6 3 0 / 7 4 1 / 8 5 2.
        let image: Vec<u8> = (0..9).collect();
        let turned = turn_clockwise(&image, SIZE, 1, 1).unwrap();
        assert_eq!(turned, [6, 3, 0, 7, 4, 1, 8, 5, 2]);
        // The right column (2, 5, 8) is now the bottom row.
        assert_eq!(&turned[6..], &[8, 5, 2]);
        for turns in 0..4u8 {
            let there = turn_clockwise(&image, SIZE, 1, turns).unwrap();
            let back = turn_clockwise(&there, SIZE, 1, (4 - turns) % 4).unwrap();
            assert_eq!(back, image, "{turns} turns and back");
        }
        // Channels travel with their pixel.
        let rgb: Vec<u8> = (0..27).collect();
        let turned = turn_clockwise(&rgb, SIZE, 3, 1).unwrap();
        assert_eq!(&turned[..3], &[18, 19, 20]);
        assert!(turn_clockwise(&rgb, ImageSize::new(3, 9), 1, 1).is_err());
        assert!(turn_clockwise(&rgb, SIZE, 1, 1).is_err());
        // An empty image turns to itself.
        assert_eq!(
            turn_clockwise::<u8>(&[], ImageSize::square(0), 3, 1),
            Ok(vec![])
        );
    }
}
