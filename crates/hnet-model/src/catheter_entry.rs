//! The edge of a view through which the catheter enters it, and reading a view as if its catheter
//! came up from the bottom.
//!
//! Every H-Net trained here saw catheters that come up from the bottom edge of both views (the
//! bench, and the twin's scenes at the page's C-arm angles), and one with position channels loses
//! the shaft of a catheter that enters through another edge (catheter IoU about 0.2; see
//! docs/log/2026-12-01-training-on-the-twins-stream.md, "Turned at evaluation"). Turning a view by quarter turns so that its catheter
//! enters from the bottom, and the masks back, reads such a view without retraining.
//!
//! When the edge is not known, [`EntrySetting::Search`] runs the four turns of both views and
//! keeps, per view, the turn whose mask has the most catheter pixels: the shaft a turned view
//! loses is most of the catheter (on 2,400 twin views the bundled model's upright turn had the
//! most for all but 2; docs/log/2026-12-01-training-on-the-twins-stream.md, "Where the catheter
//! enters").
//!
//! The force head learned the bench with both views as they are, so its force is kept only when
//! both views were read untouched ([`EntryReading::force`]).
//!
//! Turning is exact on the pixel grid (no resampling), for square images only.

use alloc::string::String;
use alloc::vec::Vec;

use hnet_units::ImageSize;

use burn::tensor::Device;

use crate::inference::{PredictError, StereoPair, StereoPrediction};
use crate::metrics::MASK_THRESHOLD;
use crate::model::HNet;

/// The edge of a view through which the catheter enters the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum CatheterEntry {
    /// The bottom edge, as in every training scene.
    #[default]
    Bottom,
    /// The right edge.
    Right,
    /// The top edge.
    Top,
    /// The left edge.
    Left,
}

impl CatheterEntry {
    /// Every edge, in the order of [`CatheterEntry::quarter_turns`].
    pub const ALL: [Self; 4] = [Self::Bottom, Self::Right, Self::Top, Self::Left];

    /// Clockwise quarter turns that bring this edge to the bottom of the view (a clockwise turn
    /// takes the right edge to the bottom).
    pub fn quarter_turns(self) -> u8 {
        match self {
            Self::Bottom => 0,
            Self::Right => 1,
            Self::Top => 2,
            Self::Left => 3,
        }
    }

    /// The edge's name in lower case, as the command line and the page write it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Bottom => "bottom",
            Self::Right => "right",
            Self::Top => "top",
            Self::Left => "left",
        }
    }

    /// The edge a [`CatheterEntry::name`] names.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }
}

/// How the catheter's entry edge of each view is found. The default reads the views as they are
/// ([`EntrySetting::AS_TRAINED`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntrySetting {
    /// The edges of views A and B are known; each view is read once.
    Known([CatheterEntry; 2]),
    /// The edges are not known: both views are read in all four turns (four times the work)
    /// and each keeps the turn whose mask has the most catheter pixels.
    Search,
}

impl Default for EntrySetting {
    fn default() -> Self {
        Self::AS_TRAINED
    }
}

impl EntrySetting {
    /// Both views entered from the bottom: the views are read as they are.
    pub const AS_TRAINED: Self = Self::Known([CatheterEntry::Bottom; 2]);

    /// The entry edges of views A and B to read the pair with: one pair of edges when they are
    /// known, all four (the same for both views) in a search.
    pub fn candidates(self) -> Vec<[CatheterEntry; 2]> {
        match self {
            Self::Known(entry) => alloc::vec![entry],
            Self::Search => CatheterEntry::ALL.iter().map(|&e| [e, e]).collect(),
        }
    }

    /// Whether this setting reads anything but the views as they are.
    pub fn turns_views(self) -> bool {
        self != Self::AS_TRAINED
    }

    /// Whether this setting can keep the force head's force for a pair: not when it turns a
    /// view of every pair ([`EntryReading::force`]).
    pub fn can_read_force(self) -> bool {
        self == Self::Search || !self.turns_views()
    }

    /// The setting a text names: `auto` (a search), one edge's [`CatheterEntry::name`] for both
    /// views, or two comma-separated for views A and B (`bottom,left`).
    pub fn from_text(text: &str) -> Option<Self> {
        let text = text.trim();
        if text == "auto" {
            return Some(Self::Search);
        }
        let mut edges = text.split(',').map(|e| CatheterEntry::from_name(e.trim()));
        let a = edges.next()??;
        let b = edges.next().unwrap_or(Some(a))?;
        edges.next().is_none().then_some(Self::Known([a, b]))
    }

    /// The setting in [`EntrySetting::from_text`]'s words (one edge when both views share it).
    pub fn text(self) -> String {
        match self {
            Self::Search => "auto".into(),
            Self::Known([a, b]) if a == b => a.name().into(),
            Self::Known([a, b]) => alloc::format!("{},{}", a.name(), b.name()),
        }
    }
}

/// An image to be turned is not a square of the expected size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "cannot turn a view of {size} with {found} values ({channels} per pixel): only square \
     images of the network's input size can be turned"
)]
pub struct TurnError {
    /// The image size.
    pub size: ImageSize,
    /// Values per pixel.
    pub channels: usize,
    /// Values found.
    pub found: usize,
}

/// `values`, a square image of `size` with `channels` interleaved values per pixel (row-major),
/// turned clockwise by `quarter_turns` (counted modulo 4).
///
/// On raw buffers, for the page and any network input; `hnet_twin::dataset::SquareSymmetry` turns
/// a dataset's decoded images (`hnet eval --turn-views`) with the `image` crate, which this
/// `no_std` crate does not use. The two conventions are checked against each other by `hnet
/// eval --turn-views 1 --catheter-entry left` reading the untouched views (crates/hnet-cli's
/// tests).
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
    let last = side - 1;
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

/// Both views of a pair turned so that their catheters enter from the bottom, as the network
/// reads them: RGB bytes, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct TurnedPair {
    /// The entry edges of views A and B this pair was turned for.
    pub entry: [CatheterEntry; 2],
    /// View A turned by `entry[0].quarter_turns()`.
    pub view_a: Vec<u8>,
    /// View B turned by `entry[1].quarter_turns()`.
    pub view_b: Vec<u8>,
}

/// The pairs to run the network on for `view_a` and `view_b` (RGB images of `size`) under
/// `setting`, one per [`EntrySetting::candidates`].
pub fn turned_pairs(
    view_a: &[u8],
    view_b: &[u8],
    size: ImageSize,
    setting: EntrySetting,
) -> Result<Vec<TurnedPair>, TurnError> {
    setting
        .candidates()
        .into_iter()
        .map(|entry| {
            Ok(TurnedPair {
                entry,
                view_a: turn_clockwise(view_a, size, 3, entry[0].quarter_turns())?,
                view_b: turn_clockwise(view_b, size, 3, entry[1].quarter_turns())?,
            })
        })
        .collect()
}

/// The network's outputs for one [`TurnedPair`], in the turned frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TurnedOutput {
    /// The entry edges the views were turned for.
    pub entry: [CatheterEntry; 2],
    /// Catheter probabilities of views A and B, row-major, as the network returned them.
    pub masks: [Vec<f32>; 2],
    /// Tip force `(Fx, Fy, Fz)` in newtons, when the network has a force head.
    pub force: Option<[f32; 3]>,
}

impl TurnedOutput {
    /// `prediction` of the pair turned for `entry`.
    pub fn from_prediction(entry: [CatheterEntry; 2], prediction: StereoPrediction) -> Self {
        Self {
            entry,
            masks: [prediction.mask_a, prediction.mask_b],
            force: Some(prediction.force),
        }
    }
}

/// What the network says about one pair read under an [`EntrySetting`].
#[derive(Debug, Clone, PartialEq)]
pub struct EntryReading {
    /// Catheter probabilities of views A and B, row-major, in each view's own frame (turned
    /// back).
    pub masks: [Vec<f32>; 2],
    /// The entry edge kept for each view.
    pub entry: [CatheterEntry; 2],
    /// The force head's tip force in newtons, when both views were read as they are (the only
    /// way it learned them) and the network has one; `None` otherwise.
    pub force: Option<[f32; 3]>,
}

impl EntryReading {
    /// Whether a view was read turned, so the force head's estimate was left out.
    pub fn turned(&self) -> bool {
        self.entry != [CatheterEntry::Bottom; 2]
    }
}

/// Pixels a mask calls catheter (probability at least [`MASK_THRESHOLD`]).
fn catheter_pixels(mask: &[f32]) -> usize {
    mask.iter().filter(|&&p| p >= MASK_THRESHOLD).count()
}

/// Reads the outputs of one pair's [`turned_pairs`] (each of `size`): per view, the only output
/// or, of several, the one with the most catheter pixels (the first of equals), turned back;
/// the force of the output whose views were both read as they are. An error when a mask is not
/// of `size`, or without outputs (no mask to turn back).
pub fn read_turned(outputs: Vec<TurnedOutput>, size: ImageSize) -> Result<EntryReading, TurnError> {
    let Some(first) = outputs.first() else {
        return Err(TurnError {
            size,
            channels: 1,
            found: 0,
        });
    };
    let mut best = [0usize; 2];
    let mut most = [0, 1].map(|view| catheter_pixels(&first.masks[view]));
    for (index, output) in outputs.iter().enumerate().skip(1) {
        for view in 0..2 {
            let pixels = catheter_pixels(&output.masks[view]);
            if pixels > most[view] {
                most[view] = pixels;
                best[view] = index;
            }
        }
    }
    let entry = [outputs[best[0]].entry[0], outputs[best[1]].entry[1]];
    let force = outputs
        .iter()
        .find(|o| o.entry == [CatheterEntry::Bottom; 2])
        .and_then(|o| o.force)
        .filter(|_| entry == [CatheterEntry::Bottom; 2]);
    let back = |view: usize| {
        let turns = entry[view].quarter_turns();
        turn_clockwise(&outputs[best[view]].masks[view], size, 1, (4 - turns) % 4)
    };
    Ok(EntryReading {
        masks: [back(0)?, back(1)?],
        entry,
        force,
    })
}

/// Why a pair could not be read with its views turned.
#[derive(Debug, thiserror::Error)]
pub enum ReadEntryError {
    /// The network could not be run.
    #[error(transparent)]
    Predict(#[from] PredictError),
    /// A view or a mask could not be turned.
    #[error(transparent)]
    Turn(#[from] TurnError),
}

impl HNet {
    /// [`HNet::predict_async`] for one pair (RGB images of `size`) under `setting`: its views
    /// turned for each candidate edge, run as one batch, read back by [`read_turned`]. (`hnet
    /// eval`, which runs every architecture, turns its batches with the same functions.)
    pub async fn predict_entry_async(
        &self,
        pair: StereoPair<'_>,
        size: ImageSize,
        device: &Device,
        setting: EntrySetting,
    ) -> Result<EntryReading, ReadEntryError> {
        let turned = turned_pairs(pair.view_a, pair.view_b, size, setting)?;
        let predictions = self.predict_async(&as_pairs(&turned), size, device).await?;
        Ok(read_predictions(&turned, predictions, size)?)
    }
}

/// `turned` as the network's input pairs.
pub fn as_pairs(turned: &[TurnedPair]) -> Vec<StereoPair<'_>> {
    turned
        .iter()
        .map(|t| StereoPair {
            view_a: &t.view_a,
            view_b: &t.view_b,
        })
        .collect()
}

/// [`read_turned`] of the network's `predictions` of `turned`, in the same order.
pub fn read_predictions(
    turned: &[TurnedPair],
    predictions: Vec<StereoPrediction>,
    size: ImageSize,
) -> Result<EntryReading, TurnError> {
    let outputs = turned
        .iter()
        .zip(predictions)
        .map(|(t, p)| TurnedOutput::from_prediction(t.entry, p))
        .collect();
    read_turned(outputs, size)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: ImageSize = ImageSize {
        width: 3,
        height: 3,
    };

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
    }

    #[test]
    fn entry_edges_round_trip_their_names() {
        for e in CatheterEntry::ALL {
            assert_eq!(CatheterEntry::from_name(e.name()), Some(e));
            assert_eq!(CatheterEntry::ALL[e.quarter_turns() as usize], e);
        }
        assert_eq!(CatheterEntry::from_name("sideways"), None);
        for text in ["auto", "left", "bottom,top"] {
            assert_eq!(EntrySetting::from_text(text).unwrap().text(), text);
        }
        assert_eq!(
            EntrySetting::from_text("top, top"),
            Some(EntrySetting::Known([CatheterEntry::Top; 2]))
        );
        for bad in ["", "up", "left,", "left,top,right"] {
            assert_eq!(EntrySetting::from_text(bad), None, "{bad:?}");
        }
    }

    /// A mask of `SIZE` with a catheter down the left column (the bottom-left pixel included).
    fn left_column() -> Vec<f32> {
        (0..9).map(|i| if i % 3 == 0 { 0.9 } else { 0.1 }).collect()
    }

    #[test]
    fn a_search_keeps_per_view_the_turn_with_the_most_catheter_and_turns_it_back() {
        let found = left_column();
        let lost = alloc::vec![0.1f32; 9];
        let output = |entry: CatheterEntry, a: &[f32], b: &[f32]| TurnedOutput {
            entry: [entry; 2],
            masks: [a.to_vec(), b.to_vec()],
            force: Some([0.1, 0.2, 0.3]),
        };
        // View A reads best as it is, view B turned for a left entry (its mask then in the
        // turned frame).
        let turned_found = turn_clockwise(&found, SIZE, 1, 3).unwrap();
        let outputs = alloc::vec![
            output(CatheterEntry::Bottom, &found, &lost),
            output(CatheterEntry::Right, &lost, &lost),
            output(CatheterEntry::Top, &lost, &lost),
            output(CatheterEntry::Left, &lost, &turned_found),
        ];
        let reading = read_turned(outputs, SIZE).unwrap();
        assert_eq!(reading.entry, [CatheterEntry::Bottom, CatheterEntry::Left]);
        assert_eq!(reading.masks, [found.clone(), found.clone()]);
        // A turned view: the force head's estimate is left out.
        assert!(reading.turned());
        assert_eq!(reading.force, None);

        // Ties keep the views as they are, with the force.
        let outputs = CatheterEntry::ALL
            .map(|e| output(e, &found, &found))
            .to_vec();
        let reading = read_turned(outputs, SIZE).unwrap();
        assert_eq!(reading.entry, [CatheterEntry::Bottom; 2]);
        assert_eq!(reading.force, Some([0.1, 0.2, 0.3]));
        assert!(read_turned(Vec::new(), SIZE).is_err());
    }

    #[test]
    fn known_edges_read_each_view_once_turned_for_its_edge() {
        let a: Vec<u8> = (0..27).collect();
        let b: Vec<u8> = (27..54).collect();
        let setting = EntrySetting::Known([CatheterEntry::Bottom, CatheterEntry::Top]);
        assert!(setting.turns_views());
        assert!(!EntrySetting::AS_TRAINED.turns_views());
        // A pair read with a view turned keeps no force of the head's; a search may read both
        // views as they are.
        assert!(!setting.can_read_force());
        assert!(EntrySetting::AS_TRAINED.can_read_force());
        assert!(EntrySetting::Search.can_read_force());
        let pairs = turned_pairs(&a, &b, SIZE, setting).unwrap();
        assert_eq!(pairs.len(), 1);
        assert_eq!(pairs[0].view_a, a);
        assert_eq!(pairs[0].view_b, turn_clockwise(&b, SIZE, 3, 2).unwrap());
        assert_eq!(
            turned_pairs(&a, &b, SIZE, EntrySetting::Search)
                .unwrap()
                .len(),
            4
        );
    }
}
