//! The edge of a view through which the catheter enters it, and reading a view as if its catheter
//! came up from the bottom.
//!
//! Every H-Net trained here saw catheters that come up from the bottom edge of both views (the
//! bench, and the twin's scenes at the page's C-arm angles), and one with position channels loses
//! the shaft of a catheter that enters through another edge (catheter IoU about 0.2; see
//! docs/log/2026-12-01-training-on-the-twins-stream.md, "Turned at evaluation"). Turning a view by quarter turns so that its catheter
//! enters from the bottom, and the masks back, reads such a view without retraining.
//!
//! When the edge is not known, a search keeps, per view, the turn whose mask has the most
//! catheter pixels: the shaft a turned view loses is most of the catheter (on 2,400 twin views
//! the bundled model's upright turn had the most for all but 2;
//! docs/log/2026-12-01-training-on-the-twins-stream.md, "Where the catheter enters").
//! [`EntrySetting::Search`] reads both views as they are first and turns only a view whose mask
//! does not reach the bottom edge ([`reaches_bottom`]): a catheter read as trained is a shaft
//! that leaves the view through its bottom, so one pass settles most pairs.
//! [`EntrySetting::EveryTurn`] reads every view at all four turns (four passes).
//! [`EntrySearch`] holds one pair's search, for whoever runs the network.
//!
//! The force head learned the bench with both views as they are, so its force is kept only when
//! both views were read untouched ([`EntryReading::force`]).
//!
//! Turning is [`hnet_units::turn::turn_clockwise`]: exact on the pixel grid (no resampling), for
//! square images only.

use alloc::string::String;
use alloc::vec::Vec;

use hnet_units::mask::{MaskAveraging, is_catheter};
use hnet_units::turn::{TurnError, turn_clockwise};
use hnet_units::{ImageSize, TipForce, View};

use burn::tensor::Device;

use crate::inference::{PredictError, StereoPair, StereoPrediction};
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
    /// The edges are not known: both views are read as they are, and a view whose mask does
    /// not reach the bottom edge is read in the other three turns too; each view keeps the
    /// turn whose mask has the most catheter pixels.
    Search,
    /// The edges are not known: both views are read in all four turns (four times the work)
    /// and each keeps the turn whose mask has the most catheter pixels.
    EveryTurn,
}

impl Default for EntrySetting {
    fn default() -> Self {
        Self::AS_TRAINED
    }
}

impl EntrySetting {
    /// Both views entered from the bottom: the views are read as they are.
    pub const AS_TRAINED: Self = Self::Known([CatheterEntry::Bottom; 2]);

    /// The entry edges of views A and B the pair is read with first: the known ones, or both
    /// views as they are in a search.
    pub fn first_reading(self) -> [CatheterEntry; 2] {
        match self {
            Self::Known(entry) => entry,
            Self::Search | Self::EveryTurn => [CatheterEntry::Bottom; 2],
        }
    }

    /// Whether this setting searches for the edges.
    pub fn searches(self) -> bool {
        matches!(self, Self::Search | Self::EveryTurn)
    }

    /// Whether this setting reads anything but the views as they are.
    pub fn turns_views(self) -> bool {
        self != Self::AS_TRAINED
    }

    /// Whether this setting can keep the force head's force for a pair: not when it turns a
    /// view of every pair ([`EntryReading::force`]).
    pub fn can_read_force(self) -> bool {
        self.searches() || !self.turns_views()
    }

    /// The setting a text names: `auto` (a search), `every-turn` (a search at all four turns),
    /// one edge's [`CatheterEntry::name`] for both views, or two comma-separated for views A and
    /// B (`bottom,left`).
    pub fn from_text(text: &str) -> Option<Self> {
        let text = text.trim();
        match text {
            "auto" => return Some(Self::Search),
            "every-turn" => return Some(Self::EveryTurn),
            _ => {}
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
            Self::EveryTurn => "every-turn".into(),
            Self::Known([a, b]) if a == b => a.name().into(),
            Self::Known([a, b]) => alloc::format!("{},{}", a.name(), b.name()),
        }
    }
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

/// `view_a` and `view_b` (RGB images of `size`) turned for the entry edges `entry`.
pub fn turned_pair(
    view_a: &[u8],
    view_b: &[u8],
    size: ImageSize,
    entry: [CatheterEntry; 2],
) -> Result<TurnedPair, TurnError> {
    Ok(TurnedPair {
        entry,
        view_a: turn_clockwise(view_a, size, 3, entry[0].quarter_turns())?,
        view_b: turn_clockwise(view_b, size, 3, entry[1].quarter_turns())?,
    })
}

/// The network's outputs for one [`TurnedPair`], in the turned frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TurnedOutput {
    /// The entry edges the views were turned for.
    pub entry: [CatheterEntry; 2],
    /// Catheter probabilities of views A and B, row-major, as the network returned them.
    pub masks: [Vec<f32>; 2],
    /// Tip force `(Fx, Fy, Fz)` in newtons, when the network has a force head.
    pub force: Option<TipForce>,
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
    pub force: Option<TipForce>,
}

impl EntryReading {
    /// Whether a view was read turned, so the force head's estimate was left out.
    pub fn turned(&self) -> bool {
        self.entry != [CatheterEntry::Bottom; 2]
    }
}

/// Pixels a mask calls catheter ([`is_catheter`]).
fn catheter_pixels(mask: &[f32]) -> usize {
    mask.iter().filter(|&&p| is_catheter(p)).count()
}

/// The least share of a view's height that the catheter pixels 8-connected to its bottom row
/// must span for [`reaches_bottom`]: a shaft, not a blob. On 240 off-bench pairs read by the
/// bundled model (docs/results.md, "Where the catheter enters") a catheter read as trained
/// spanned 51-176 of 224 rows; in views turned away from the bottom, what the upright reading
/// left in the bottom band spanned 0-2 rows in most views and 45 or more in 4-6 of 480.
pub const SHAFT_FROM_BOTTOM_MIN_SHARE: f64 = 0.2;

/// Whether a view's mask (catheter probabilities, row-major, of `size`), read as it is, enters
/// through the bottom edge: its bottom rows (a band 1/32 of the side deep, at least one pixel)
/// hold at least one catheter pixel per row, no other edge's band holds more, and the catheter
/// pixels 8-connected to the bottom row span [`SHAFT_FROM_BOTTOM_MIN_SHARE`] of the height. The
/// shaft of a catheter read as trained leaves the view through its bottom; a view read upright
/// whose catheter enters elsewhere loses most of its shaft, and what is left seldom reaches the
/// bottom as a shaft.
pub fn reaches_bottom(mask: &[f32], size: ImageSize) -> bool {
    let (width, height) = (size.width, size.height);
    if width == 0 || height == 0 || mask.len() != width * height {
        return false;
    }
    let band = (width.min(height) / 32).max(1);
    let catheter = |row: usize, col: usize| usize::from(is_catheter(mask[row * width + col]));
    let rows = |from: usize| -> usize {
        (from..from + band)
            .map(|r| (0..width).map(|c| catheter(r, c)).sum::<usize>())
            .sum()
    };
    let cols = |from: usize| -> usize {
        (from..from + band)
            .map(|c| (0..height).map(|r| catheter(r, c)).sum::<usize>())
            .sum()
    };
    let bottom = rows(height - band);
    bottom >= band
        && [rows(0), cols(0), cols(width - band)]
            .iter()
            .all(|&edge| edge <= bottom)
        && rows_spanned_from_bottom(mask, size) as f64
            >= SHAFT_FROM_BOTTOM_MIN_SHARE * height as f64
}

/// Rows spanned by the catheter pixels of `mask` (of `size`, checked by the caller) that are
/// 8-connected to its bottom row: 0 when none is on the bottom row.
fn rows_spanned_from_bottom(mask: &[f32], size: ImageSize) -> usize {
    let (width, height) = (size.width, size.height);
    let mut seen = alloc::vec![false; mask.len()];
    let mut stack: Vec<usize> = ((height - 1) * width..height * width)
        .filter(|&i| is_catheter(mask[i]))
        .collect();
    for &i in &stack {
        seen[i] = true;
    }
    let mut top = height;
    while let Some(i) = stack.pop() {
        let (row, col) = (i / width, i % width);
        top = top.min(row);
        for r in row.saturating_sub(1)..=(row + 1).min(height - 1) {
            for c in col.saturating_sub(1)..=(col + 1).min(width - 1) {
                let j = r * width + c;
                if !seen[j] && is_catheter(mask[j]) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
    }
    height.saturating_sub(top)
}

/// One pair's search for its views' entry edges under an [`EntrySetting`]: the first reading
/// ([`EntrySetting::first_reading`]), then the turns [`EntrySearch::further`] asks for, per
/// view. Whoever runs the network (the page's workers one view at a time, `hnet eval` in
/// batches) feeds the readings in; [`EntrySearch::finish`] keeps per view the turn with the most
/// catheter pixels (the first of equals: the first reading) and turns its mask back.
#[derive(Debug, Clone)]
pub struct EntrySearch {
    size: ImageSize,
    first: [CatheterEntry; 2],
    further: [Vec<CatheterEntry>; 2],
    /// Per view, its readings so far: the edge and the mask in the turned frame.
    readings: [Vec<(CatheterEntry, Vec<f32>)>; 2],
    /// The force head's estimate of the first reading.
    force: Option<TipForce>,
}

/// The edges a search reads a view at after reading it as it is.
const OTHER_EDGES: [CatheterEntry; 3] = [
    CatheterEntry::Right,
    CatheterEntry::Top,
    CatheterEntry::Left,
];

impl EntrySearch {
    /// The search of one pair of views of `size` under `setting`, from the network's output
    /// for the pair turned for `setting.first_reading()`.
    pub fn new(setting: EntrySetting, size: ImageSize, first: TurnedOutput) -> Self {
        let TurnedOutput {
            entry,
            masks: [mask_a, mask_b],
            force,
        } = first;
        let further = [&mask_a, &mask_b].map(|mask| match setting {
            EntrySetting::Known(_) => Vec::new(),
            EntrySetting::EveryTurn => OTHER_EDGES.to_vec(),
            EntrySetting::Search if reaches_bottom(mask, size) => Vec::new(),
            EntrySetting::Search => OTHER_EDGES.to_vec(),
        });
        Self {
            size,
            first: entry,
            further,
            readings: [
                alloc::vec![(entry[0], mask_a)],
                alloc::vec![(entry[1], mask_b)],
            ],
            force,
        }
    }

    /// The further edges each view is to be read at (view A's, view B's); none once the first
    /// reading settles them.
    pub fn further(&self) -> &[Vec<CatheterEntry>; 2] {
        &self.further
    }

    /// The further readings as pairs, for a runner that reads pairs: each edge some view asks
    /// for, both views turned for it ([`EntrySearch::add_pair`] keeps only the views that
    /// asked).
    pub fn further_pairs(&self) -> Vec<[CatheterEntry; 2]> {
        OTHER_EDGES
            .into_iter()
            .filter(|edge| self.further.iter().any(|f| f.contains(edge)))
            .map(|edge| [edge; 2])
            .collect()
    }

    /// `view`'s mask read turned for `entry` (in the turned frame).
    pub fn add(&mut self, view: View, entry: CatheterEntry, mask: Vec<f32>) {
        self.readings[view.index()].push((entry, mask));
    }

    /// The network's output for the pair turned for `output.entry`: each view that asked for
    /// its edge gets its mask.
    pub fn add_pair(&mut self, output: TurnedOutput) {
        let [mask_a, mask_b] = output.masks;
        for (view, mask) in [(View::A, mask_a), (View::B, mask_b)] {
            let entry = output.entry[view.index()];
            if self.further[view.index()].contains(&entry) {
                self.add(view, entry, mask);
            }
        }
    }

    /// What the search found: per view, the reading with the most catheter pixels (the first of
    /// equals), turned back; the force head's estimate when both views were read, and kept, as
    /// they are. An error when a mask is not of the search's size.
    pub fn finish(self) -> Result<EntryReading, TurnError> {
        let size = self.size;
        let keep = |readings: [Vec<(CatheterEntry, Vec<f32>)>; 2]| {
            readings.map(|readings| {
                let mut best = 0;
                let mut most = catheter_pixels(&readings[0].1);
                for (index, (_, mask)) in readings.iter().enumerate().skip(1) {
                    let pixels = catheter_pixels(mask);
                    if pixels > most {
                        (best, most) = (index, pixels);
                    }
                }
                readings.into_iter().nth(best).unwrap_or_default()
            })
        };
        let [(entry_a, mask_a), (entry_b, mask_b)] = keep(self.readings);
        let entry = [entry_a, entry_b];
        let back = |mask: &[f32], edge: CatheterEntry| {
            turn_clockwise(mask, size, 1, (4 - edge.quarter_turns()) % 4)
        };
        let upright = [CatheterEntry::Bottom; 2];
        Ok(EntryReading {
            masks: [back(&mask_a, entry_a)?, back(&mask_b, entry_b)?],
            entry,
            force: self
                .force
                .filter(|_| entry == upright && self.first == upright),
        })
    }

    /// Readings this search took per view so far (for the cost of a search).
    pub fn readings(&self) -> [usize; 2] {
        self.readings.each_ref().map(Vec::len)
    }
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
    /// [`HNet::predict_async`] for one pair (RGB images of `size`) under `setting`: the first
    /// reading, then the further turns its [`EntrySearch`] asks for in one batch, each view read
    /// as `averaging` says. (`hnet eval`,
    /// which runs every architecture, searches its batches with the same [`EntrySearch`].)
    pub async fn predict_entry_async(
        &self,
        pair: StereoPair<'_>,
        size: ImageSize,
        device: &Device,
        setting: EntrySetting,
        averaging: MaskAveraging,
    ) -> Result<EntryReading, ReadEntryError> {
        let first = turned_pair(pair.view_a, pair.view_b, size, setting.first_reading())?;
        let output = self
            .turned_outputs(core::slice::from_ref(&first), size, device, averaging)
            .await?
            .pop()
            .ok_or(TurnError {
                size,
                channels: 1,
                found: 0,
            })?;
        let mut search = EntrySearch::new(setting, size, output);
        let further = search
            .further_pairs()
            .into_iter()
            .map(|entry| turned_pair(pair.view_a, pair.view_b, size, entry))
            .collect::<Result<Vec<_>, _>>()?;
        if !further.is_empty() {
            for output in self
                .turned_outputs(&further, size, device, averaging)
                .await?
            {
                search.add_pair(output);
            }
        }
        Ok(search.finish()?)
    }

    /// The network's outputs for `turned` (images of `size`), run as one batch.
    async fn turned_outputs(
        &self,
        turned: &[TurnedPair],
        size: ImageSize,
        device: &Device,
        averaging: MaskAveraging,
    ) -> Result<Vec<TurnedOutput>, PredictError> {
        let predictions = self
            .predict_async(&as_pairs(turned), size, device, averaging)
            .await?;
        Ok(turned
            .iter()
            .zip(predictions)
            .map(|(t, p)| TurnedOutput::from_prediction(t.entry, p))
            .collect())
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

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: ImageSize = ImageSize {
        width: 3,
        height: 3,
    };

    #[test]
    fn entry_edges_round_trip_their_names() {
        for e in CatheterEntry::ALL {
            assert_eq!(CatheterEntry::from_name(e.name()), Some(e));
            assert_eq!(CatheterEntry::ALL[e.quarter_turns() as usize], e);
        }
        assert_eq!(CatheterEntry::from_name("sideways"), None);
        for text in ["auto", "every-turn", "left", "bottom,top"] {
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

    /// A mask of `SIZE` with a catheter down the middle column, from the top edge to the
    /// bottom one.
    fn middle_column() -> Vec<f32> {
        (0..9).map(|i| if i % 3 == 1 { 0.9 } else { 0.1 }).collect()
    }

    /// The network's output for a pair turned for `entry` (both views).
    fn output(entry: CatheterEntry, a: &[f32], b: &[f32]) -> TurnedOutput {
        TurnedOutput {
            entry: [entry; 2],
            masks: [a.to_vec(), b.to_vec()],
            force: Some(TipForce::new(0.1, 0.2, 0.3)),
        }
    }

    #[test]
    fn a_search_keeps_per_view_the_turn_with_the_most_catheter_and_turns_it_back() {
        let found = middle_column();
        let lost = alloc::vec![0.1f32; 9];
        // View A reads best as it is, view B turned for a left entry (its mask then in the
        // turned frame).
        let turned_found = turn_clockwise(&found, SIZE, 1, 3).unwrap();
        let mut search = EntrySearch::new(
            EntrySetting::EveryTurn,
            SIZE,
            output(CatheterEntry::Bottom, &found, &lost),
        );
        assert_eq!(search.further_pairs().len(), 3);
        search.add_pair(output(CatheterEntry::Right, &lost, &lost));
        search.add_pair(output(CatheterEntry::Top, &lost, &lost));
        search.add_pair(output(CatheterEntry::Left, &lost, &turned_found));
        assert_eq!(search.readings(), [4, 4]);
        let reading = search.finish().unwrap();
        assert_eq!(reading.entry, [CatheterEntry::Bottom, CatheterEntry::Left]);
        assert_eq!(reading.masks, [found.clone(), found.clone()]);
        // A turned view: the force head's estimate is left out.
        assert!(reading.turned());
        assert_eq!(reading.force, None);

        // Ties keep the views as they are, with the force.
        let mut search = EntrySearch::new(
            EntrySetting::EveryTurn,
            SIZE,
            output(CatheterEntry::Bottom, &found, &found),
        );
        for edge in OTHER_EDGES {
            search.add_pair(output(edge, &found, &found));
        }
        let reading = search.finish().unwrap();
        assert_eq!(reading.entry, [CatheterEntry::Bottom; 2]);
        assert_eq!(reading.force, Some(TipForce::new(0.1, 0.2, 0.3)));
    }

    #[test]
    fn a_search_turns_only_a_view_whose_mask_does_not_reach_the_bottom() {
        let found = middle_column();
        assert!(reaches_bottom(&found, SIZE));
        // A catheter down the left column reaches the bottom, but the left edge more.
        let left: Vec<f32> = (0..9).map(|i| if i % 3 == 0 { 0.9 } else { 0.0 }).collect();
        assert!(!reaches_bottom(&left, SIZE));
        // A blob in the bottom band is not a shaft: at 20 x 20 the catheter pixels connected to
        // the bottom row must span 4 rows.
        let square = ImageSize::square(20);
        let shaft = |rows: usize| -> Vec<f32> {
            (0..400)
                .map(|i| {
                    if i % 20 == 10 && i / 20 >= 20 - rows {
                        0.9
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        assert!(!reaches_bottom(&shaft(3), square));
        assert!(reaches_bottom(&shaft(4), square));
        // A catheter in the top row only: its view is read in the other three turns.
        let top: Vec<f32> = (0..9).map(|i| if i < 3 { 0.9 } else { 0.0 }).collect();
        assert!(!reaches_bottom(&top, SIZE));
        assert!(!reaches_bottom(&top[..2], SIZE));
        let mut search = EntrySearch::new(
            EntrySetting::Search,
            SIZE,
            output(CatheterEntry::Bottom, &found, &top),
        );
        assert_eq!(search.further(), &[Vec::new(), OTHER_EDGES.to_vec()]);
        // View B read turned for a top entry finds the whole catheter; view A's further
        // readings are not asked for, and a pair's output only gives B its mask.
        let whole = alloc::vec![0.9f32; 9];
        search.add_pair(output(CatheterEntry::Top, &whole, &whole));
        search.add(View::B, CatheterEntry::Right, top.clone());
        assert_eq!(search.readings(), [1, 3]);
        let reading = search.finish().unwrap();
        assert_eq!(reading.entry, [CatheterEntry::Bottom, CatheterEntry::Top]);
        assert_eq!(reading.masks[0], found);
        assert_eq!(reading.force, None);
        // Known edges are read once.
        let known = EntrySearch::new(
            EntrySetting::Known([CatheterEntry::Left; 2]),
            SIZE,
            output(CatheterEntry::Left, &top, &top),
        );
        assert!(known.further_pairs().is_empty());
        let reading = known.finish().unwrap();
        assert_eq!(reading.entry, [CatheterEntry::Left; 2]);
        assert_eq!(reading.force, None);
        // A mask of another size cannot be turned back.
        let wrong = EntrySearch::new(
            EntrySetting::Search,
            SIZE,
            output(CatheterEntry::Bottom, &found[..4], &found),
        );
        assert!(wrong.finish().is_err());
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
        let pair = turned_pair(&a, &b, SIZE, setting.first_reading()).unwrap();
        assert_eq!(pair.view_a, a);
        assert_eq!(pair.view_b, turn_clockwise(&b, SIZE, 3, 2).unwrap());
        for search in [EntrySetting::Search, EntrySetting::EveryTurn] {
            assert!(search.searches() && search.can_read_force());
            assert_eq!(search.first_reading(), [CatheterEntry::Bottom; 2]);
        }
    }
}
