//! The labeling work: stereo pairs with their (corrected) masks and force labels, and undo and
//! redo per brush stroke. Plain data, so it can be stored in the browser and exported.
//!
//! Images and masks are [`WORK_SIZE`] pixels, row-major; pixel `(x, y)` covers
//! `[x, x+1) x [y, y+1)` in image coordinates (origin at the top-left corner, `y` down).

use hnet_twin::dataset::label_origin::LabelOrigin;
use hnet_twin::dataset::{Split, next_split};
use hnet_twin::simulator::carm::Biplane;
use serde::{Deserialize, Serialize};

use crate::force_label::ForceLabelRow;
use crate::imaging::WORK_SIZE;
/// The two views of a pair (one type for the page, the network and the twin).
pub use hnet_units::View;
use hnet_units::{ImageSize, TipForce};

/// Where a pair came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum PairSource {
    /// Two image files.
    Upload {
        /// View A's file name.
        view_a: String,
        /// View B's file name.
        view_b: String,
        /// The C-arms the user stated the pair was taken with (at [`WORK_SIZE`]); `None`: not
        /// stated, and the 3D step assumes the page's default biplane (frontal and lateral).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        views: Option<Biplane>,
    },
    /// The live digital twin, with its ground truth.
    Twin {
        /// The true tip force `(Fx, Fy, Fz)` in newtons, world frame.
        true_force_n: TipForce,
        /// The true tip position in millimetres, world frame.
        tip_mm: [f64; 3],
        /// The views it was rendered with (at [`WORK_SIZE`]).
        views: Biplane,
        /// The twin's settings, as recorded with exported pairs.
        settings: serde_json::Value,
    },
    /// A frame of a biplane DICOM cine. Nothing from the files' headers is kept but the
    /// geometry and the frame's time: no file name, no patient or institution attribute.
    Dicom {
        /// The frame, 0-based, in both planes.
        frame: usize,
        /// Its time after plane A's first frame, seconds, when the headers give it.
        time_s: Option<f64>,
        /// Both planes' C-arms at [`WORK_SIZE`], from the headers (defaults where they lacked
        /// an attribute).
        views: Biplane,
        /// The geometry attributes each plane's headers lacked (DICOM keywords), A then B.
        missing_geometry: [Vec<String>; 2],
    },
}

/// One stereo pair being labeled, at [`WORK_SIZE`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabeledPair {
    /// Stable id (also the exported id): ASCII letters, digits, `-`, `_`, `.`.
    pub id: String,
    /// Where it came from.
    pub source: PairSource,
    /// View A, RGB bytes.
    pub view_a: Vec<u8>,
    /// View B, RGB bytes.
    pub view_b: Vec<u8>,
    /// Label mask of view A (0 background, 255 catheter).
    pub mask_a: Vec<u8>,
    /// Label mask of view B.
    pub mask_b: Vec<u8>,
    /// Whether the masks hold a label yet (H-Net's pre-labels, the twin's exact masks or the
    /// user's strokes).
    pub masks_labeled: bool,
    /// The force label `(Fx, Fy, Fz)` in newtons, once entered, imported or accepted.
    pub force_n: Option<TipForce>,
    /// Where the force label came from (meaningful only with one): typed, measured, imported,
    /// simulated, or copied from a model's estimate, which the export marks as such.
    #[serde(default)]
    pub force_origin: LabelOrigin,
    /// Views the user marked as showing no catheter on purpose (A, B): their empty masks are
    /// labels, not missing ones.
    #[serde(default)]
    pub no_catheter: [bool; 2],
    /// Its split in exported datasets, given at its first export and kept from then on (see
    /// [`export_splits`]).
    #[serde(default)]
    pub split: Option<Split>,
}

impl LabeledPair {
    /// A pair with empty masks and no force label.
    pub fn new(id: String, source: PairSource, view_a: Vec<u8>, view_b: Vec<u8>) -> Self {
        let pixels = WORK_SIZE.pixels();
        Self {
            id,
            source,
            view_a,
            view_b,
            mask_a: vec![0; pixels],
            mask_b: vec![0; pixels],
            masks_labeled: false,
            force_n: None,
            force_origin: LabelOrigin::Unrecorded,
            no_catheter: [false; 2],
            split: None,
        }
    }

    /// Whether the user marked `view` as showing no catheter on purpose.
    pub fn marked_no_catheter(&self, view: View) -> bool {
        self.no_catheter[view as usize]
    }

    /// A view's label mask.
    pub fn mask(&self, view: View) -> &[u8] {
        match view {
            View::A => &self.mask_a,
            View::B => &self.mask_b,
        }
    }

    fn mask_mut(&mut self, view: View) -> &mut Vec<u8> {
        match view {
            View::A => &mut self.mask_a,
            View::B => &mut self.mask_b,
        }
    }

    /// A view's image (RGB).
    pub fn image(&self, view: View) -> &[u8] {
        match view {
            View::A => &self.view_a,
            View::B => &self.view_b,
        }
    }

    /// The true force in newtons, for twin pairs.
    pub fn true_force(&self) -> Option<TipForce> {
        match &self.source {
            PairSource::Twin { true_force_n, .. } => Some(*true_force_n),
            PairSource::Upload { .. } | PairSource::Dicom { .. } => None,
        }
    }

    /// Whether the pair can be exported: both masks labeled, each holding a catheter or its
    /// view marked as showing none, and a force label.
    pub fn is_complete(&self) -> bool {
        self.incomplete_because().is_none()
    }

    /// Whether both masks are labels: labeled, and each holds a catheter or its view is marked
    /// as showing none (an empty mask is otherwise a label not made yet, which would teach a
    /// network "no catheter here").
    pub fn masks_complete(&self) -> bool {
        self.masks_incomplete_because().is_none()
    }

    fn masks_incomplete_because(&self) -> Option<&'static str> {
        if !self.masks_labeled {
            return Some("masks not labeled");
        }
        let empty = |view: View| self.labeled_pixels(view) == 0 && !self.marked_no_catheter(view);
        match (empty(View::A), empty(View::B)) {
            (true, true) => {
                Some("both masks are empty (paint the catheter, or mark the view as showing none)")
            }
            (true, false) => Some(
                "view A's mask is empty (paint the catheter, or mark the view as showing none)",
            ),
            (false, true) => Some(
                "view B's mask is empty (paint the catheter, or mark the view as showing none)",
            ),
            (false, false) => None,
        }
    }

    /// What keeps the pair from being exported, if anything.
    pub fn incomplete_because(&self) -> Option<&'static str> {
        self.masks_incomplete_because()
            .or(if self.force_n.is_none() {
                Some("no force label")
            } else {
                None
            })
    }

    /// Catheter pixels of a view's label mask.
    pub fn labeled_pixels(&self, view: View) -> usize {
        self.mask(view)
            .iter()
            .filter(|&&m| hnet_units::mask::is_catheter_label(m))
            .count()
    }
}

/// What a stroke paints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Tool {
    /// Adds catheter (255).
    Brush,
    /// Removes catheter (0).
    Eraser,
}

/// Paints a disc of `radius` pixels centred at `(x, y)` (image coordinates) into a mask of
/// `size` pixels; returns whether anything changed.
pub fn paint_disc(
    mask: &mut [u8],
    size: ImageSize,
    x: f64,
    y: f64,
    radius: f64,
    tool: Tool,
) -> bool {
    let value = match tool {
        Tool::Brush => 255,
        Tool::Eraser => 0,
    };
    let r = radius.max(0.5);
    let (last_x, last_y) = (size.width as f64 - 1.0, size.height as f64 - 1.0);
    let (x0, x1) = ((x - r).floor().max(0.0), (x + r).ceil().min(last_x));
    let (y0, y1) = ((y - r).floor().max(0.0), (y + r).ceil().min(last_y));
    if x1 < x0 || y1 < y0 {
        return false;
    }
    let mut changed = false;
    for py in y0 as usize..=y1 as usize {
        for px in x0 as usize..=x1 as usize {
            let (dx, dy) = (px as f64 + 0.5 - x, py as f64 + 0.5 - y);
            if dx * dx + dy * dy <= r * r {
                let m = &mut mask[py * size.width + px];
                if *m != value {
                    *m = value;
                    changed = true;
                }
            }
        }
    }
    changed
}

/// Paints a stroke segment from `from` to `to` (image coordinates) with discs every half radius
/// into a mask of `size` pixels.
pub fn paint_segment(
    mask: &mut [u8],
    size: ImageSize,
    from: [f64; 2],
    to: [f64; 2],
    radius: f64,
    tool: Tool,
) -> bool {
    let length = ((to[0] - from[0]).powi(2) + (to[1] - from[1]).powi(2)).sqrt();
    let steps = (length / (radius * 0.5).max(0.5)).ceil().max(1.0) as usize;
    let mut changed = false;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (
            from[0] + t * (to[0] - from[0]),
            from[1] + t * (to[1] - from[1]),
        );
        changed |= paint_disc(mask, size, x, y, radius, tool);
    }
    changed
}

/// One undoable change of a pair's masks: each changed view's mask before and after.
#[derive(Debug, Clone, PartialEq)]
struct Edit {
    /// When it was made: edits are numbered in order, so that a restored pair's edits go back
    /// into the history where they were.
    serial: u64,
    pair: String,
    masks: Vec<(View, Vec<u8>, Vec<u8>)>,
    labeled_before: bool,
}

/// A pair taken out of the workspace, kept so that its deletion can be undone.
#[derive(Debug, Clone, PartialEq)]
pub struct RemovedPair {
    /// Its position in the pair list.
    pub index: usize,
    /// The pair, with its masks and force label.
    pub pair: LabeledPair,
    undo: Vec<Edit>,
}

/// The workspace: pairs, the one on screen, and the stroke history.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Workspace {
    /// All pairs, in the order they were added.
    pub pairs: Vec<LabeledPair>,
    /// Index of the pair on screen.
    pub current: Option<usize>,
    undo: Vec<Edit>,
    redo: Vec<Edit>,
    /// The stroke in progress: pair, view, and its mask before the stroke.
    stroke_start: Option<(String, View, Vec<u8>, bool)>,
    /// The number of the next edit.
    next_serial: u64,
}

/// Undo steps kept.
const HISTORY: usize = 100;

impl Workspace {
    /// A workspace holding `pairs` (restored from storage), the last one on screen.
    pub fn from_pairs(pairs: Vec<LabeledPair>) -> Self {
        let current = pairs.len().checked_sub(1);
        Self {
            pairs,
            current,
            ..Self::default()
        }
    }

    /// The pair on screen.
    pub fn current(&self) -> Option<&LabeledPair> {
        self.current.and_then(|i| self.pairs.get(i))
    }

    /// The pair on screen, to change.
    pub fn current_mut(&mut self) -> Option<&mut LabeledPair> {
        self.current.and_then(|i| self.pairs.get_mut(i))
    }

    /// The pair with `id`.
    pub fn pair(&self, id: &str) -> Option<&LabeledPair> {
        self.pairs.iter().find(|p| p.id == id)
    }

    /// A fresh id (`pair-0001`, `pair-0002`, ...), never one in use.
    pub fn next_id(&self) -> String {
        let n = self
            .pairs
            .iter()
            .filter_map(|p| p.id.strip_prefix("pair-")?.parse::<usize>().ok())
            .max()
            .map_or(1, |n| n + 1);
        format!("pair-{n:04}")
    }

    /// Adds a pair and shows it.
    pub fn add(&mut self, pair: LabeledPair) {
        self.pairs.push(pair);
        self.current = Some(self.pairs.len() - 1);
    }

    /// Shows pair `index` (ignored when out of range).
    pub fn select(&mut self, index: usize) {
        if index < self.pairs.len() {
            self.current = Some(index);
        }
    }

    /// Shows the next (`step` = 1) or previous (`step` = -1) pair, wrapping around.
    pub fn step(&mut self, step: isize) {
        let n = self.pairs.len() as isize;
        if n > 0 {
            let i = self.current.map_or(0, |i| i as isize);
            self.current = Some((i + step).rem_euclid(n) as usize);
        }
    }

    /// Removes the pair on screen; returns it with where it was and its undo history, so that
    /// [`Workspace::restore`] can put it back as it was.
    pub fn remove_current(&mut self) -> Option<RemovedPair> {
        let index = self.current?;
        let pair = self.pairs.remove(index);
        let (undo, kept): (Vec<Edit>, Vec<Edit>) =
            self.undo.drain(..).partition(|e| e.pair == pair.id);
        self.undo = kept;
        self.redo.retain(|e| e.pair != pair.id);
        self.current = if self.pairs.is_empty() {
            None
        } else {
            Some(index.min(self.pairs.len() - 1))
        };
        Some(RemovedPair { index, pair, undo })
    }

    /// Puts a removed pair back at its place, with its mask history, and shows it. Returns its
    /// id, or `None` when a pair with that id was added since (nothing is replaced).
    pub fn restore(&mut self, removed: RemovedPair) -> Option<String> {
        if self.pair(&removed.pair.id).is_some() {
            return None;
        }
        let index = removed.index.min(self.pairs.len());
        let id = removed.pair.id.clone();
        self.pairs.insert(index, removed.pair);
        self.undo.extend(removed.undo);
        self.undo.sort_by_key(|e| e.serial);
        let excess = self.undo.len().saturating_sub(HISTORY);
        self.undo.drain(..excess);
        self.current = Some(index);
        Some(id)
    }

    /// Starts a stroke on `view` of the pair on screen. A view whose label mask is still empty
    /// starts from `start_from` (H-Net's mask of it, binarized) when given, so that a correction
    /// is an edit of H-Net's mask rather than a redraw; the stroke's undo step takes both away.
    pub fn begin_stroke(&mut self, view: View, start_from: Option<Vec<u8>>) {
        let Some(pair) = self.current_mut() else {
            return;
        };
        let before = pair.mask(view).to_vec();
        let start = (pair.id.clone(), view, before.clone(), pair.masks_labeled);
        let marked_empty = pair.marked_no_catheter(view);
        if let Some(seed) = start_from.filter(|seed| {
            !marked_empty
                && seed.len() == before.len()
                && before.iter().all(|&v| v == 0)
                && seed.iter().any(|&v| v > 0)
        }) {
            *pair.mask_mut(view) = seed;
            pair.masks_labeled = true;
        }
        self.stroke_start = Some(start);
    }

    /// Paints part of the stroke in progress (image coordinates, radius in pixels).
    pub fn stroke_to(&mut self, from: [f64; 2], to: [f64; 2], radius: f64, tool: Tool) {
        let Some((id, view, _, _)) = &self.stroke_start else {
            return;
        };
        let (id, view) = (id.clone(), *view);
        if let Some(pair) = self.pairs.iter_mut().find(|p| p.id == id)
            && paint_segment(pair.mask_mut(view), WORK_SIZE, from, to, radius, tool)
        {
            pair.masks_labeled = true;
        }
    }

    /// Whether a stroke is in progress.
    pub fn is_stroking(&self) -> bool {
        self.stroke_start.is_some()
    }

    /// Ends the stroke: one undo step if it changed the mask. Returns the changed pair's id.
    pub fn end_stroke(&mut self) -> Option<String> {
        let (id, view, before, labeled_before) = self.stroke_start.take()?;
        let pair = self.pair(&id)?;
        let after = pair.mask(view).to_vec();
        if after == before {
            return None;
        }
        self.push_edit(Edit {
            serial: 0,
            pair: id.clone(),
            masks: vec![(view, before, after)],
            labeled_before,
        });
        Some(id)
    }

    fn push_edit(&mut self, mut edit: Edit) {
        edit.serial = self.next_serial;
        self.next_serial += 1;
        self.undo.push(edit);
        if self.undo.len() > HISTORY {
            self.undo.remove(0);
        }
        self.redo.clear();
    }

    /// Replaces both label masks of the pair on screen (H-Net's pre-labels) as one undo step.
    /// Returns the pair's id when something changed.
    pub fn set_masks(&mut self, masks: [Vec<u8>; 2]) -> Option<String> {
        let pair = self.current_mut()?;
        let labeled_before = pair.masks_labeled;
        let mut changes = Vec::new();
        for (view, mask) in View::BOTH.into_iter().zip(masks) {
            if pair.mask(view) != mask.as_slice() {
                let before = std::mem::replace(pair.mask_mut(view), mask.clone());
                changes.push((view, before, mask));
            }
        }
        pair.masks_labeled = true;
        let id = pair.id.clone();
        if changes.is_empty() {
            return (!labeled_before).then_some(id);
        }
        self.push_edit(Edit {
            serial: 0,
            pair: id.clone(),
            masks: changes,
            labeled_before,
        });
        Some(id)
    }

    /// Sets (or clears) the force label of pair `id`, with where it came from; returns whether
    /// there is such a pair.
    pub fn set_force(&mut self, id: &str, label: Option<(TipForce, LabelOrigin)>) -> bool {
        match self.pairs.iter_mut().find(|p| p.id == id) {
            Some(pair) => {
                let (force_n, origin) = match label {
                    Some((force, origin)) => (Some(force), origin),
                    None => (None, LabelOrigin::Unrecorded),
                };
                pair.force_n = force_n;
                pair.force_origin = origin;
                true
            }
            None => false,
        }
    }

    /// States (or, with `None`, forgets) the C-arms uploaded pair `id` was taken with; returns
    /// whether there is such an uploaded pair.
    pub fn set_upload_views(&mut self, id: &str, stated: Option<Biplane>) -> bool {
        match self
            .pairs
            .iter_mut()
            .find(|p| p.id == id)
            .map(|p| &mut p.source)
        {
            Some(PairSource::Upload { views, .. }) => {
                *views = stated;
                true
            }
            _ => false,
        }
    }

    /// Marks (or unmarks) `view` of pair `id` as showing no catheter on purpose; returns
    /// whether there is such a pair.
    pub fn mark_no_catheter(&mut self, id: &str, view: View, none: bool) -> bool {
        match self.pairs.iter_mut().find(|p| p.id == id) {
            Some(pair) => {
                pair.no_catheter[view as usize] = none;
                true
            }
            None => false,
        }
    }

    fn apply(&mut self, edit: &Edit, forward: bool) -> Option<String> {
        let index = self.pairs.iter().position(|p| p.id == edit.pair)?;
        let pair = &mut self.pairs[index];
        for (view, before, after) in &edit.masks {
            *pair.mask_mut(*view) = if forward { after } else { before }.clone();
        }
        pair.masks_labeled = forward || edit.labeled_before;
        self.current = Some(index);
        Some(edit.pair.clone())
    }

    /// Undoes the last step and shows its pair; returns that pair's id.
    pub fn undo(&mut self) -> Option<String> {
        let edit = self.undo.pop()?;
        let id = self.apply(&edit, false);
        self.redo.push(edit);
        id
    }

    /// Redoes the last undone step and shows its pair; returns that pair's id.
    pub fn redo(&mut self) -> Option<String> {
        let edit = self.redo.pop()?;
        let id = self.apply(&edit, true);
        self.undo.push(edit);
        id
    }

    /// Whether there is something to undo, and to redo.
    pub fn can_undo_redo(&self) -> (bool, bool) {
        (!self.undo.is_empty(), !self.redo.is_empty())
    }

    /// Gives each complete pair that has no split yet its split (see [`export_splits`]) and
    /// returns their ids, to be saved.
    pub fn assign_splits(&mut self) -> Vec<String> {
        let splits = export_splits(&self.pairs);
        let mut assigned = Vec::new();
        for (pair, split) in self.pairs.iter_mut().zip(splits) {
            if pair.split.is_none() && split.is_some() {
                pair.split = split;
                assigned.push(pair.id.clone());
            }
        }
        assigned
    }

    /// Applies force labels read from a CSV file (see [`crate::force_label::parse_force_labels`]) to the pairs with
    /// those ids. Returns how many were applied and the ids that match no pair.
    pub fn apply_force_labels(&mut self, labels: &[ForceLabelRow]) -> (usize, Vec<String>) {
        let mut applied = 0;
        let mut unknown = Vec::new();
        for (id, force, origin) in labels {
            if self.set_force(id, Some((*force, origin.clone()))) {
                applied += 1;
            } else {
                unknown.push(id.clone());
            }
        }
        (applied, unknown)
    }
}

/// The split of each pair in an export: its own once it has one (it never moves); complete
/// pairs without one get theirs in id order by [`next_split`], counting the complete pairs'
/// splits, so that an export of four or more complete pairs has a validation and a test pair
/// (unless pairs that hold those splits were completed later than others). Incomplete pairs
/// without a split get none.
pub fn export_splits(pairs: &[LabeledPair]) -> Vec<Option<Split>> {
    let mut splits: Vec<Option<Split>> = pairs.iter().map(|p| p.split).collect();
    let mut counts = [0usize; 3];
    for pair in pairs.iter().filter(|p| p.is_complete()) {
        if let Some(split) = pair.split {
            counts[split as usize] += 1;
        }
    }
    let mut pending: Vec<usize> = (0..pairs.len())
        .filter(|&i| pairs[i].split.is_none() && pairs[i].is_complete())
        .collect();
    pending.sort_by(|&a, &b| pairs[a].id.cmp(&pairs[b].id));
    for i in pending {
        let split = next_split(counts);
        counts[split as usize] += 1;
        splits[i] = Some(split);
    }
    splits
}

// Native tests (`cargo test`); the browser tests are in tests/web.rs.
#[cfg(all(test, not(target_arch = "wasm32")))]
pub(crate) mod tests {
    use super::*;
    use crate::force_label::{implausible_tip_force, parse_force_labels, parse_newtons};

    /// A workspace of `n` black uploaded pairs, `pair-0001` to `pair-000n` (also the export's
    /// tests).
    pub(crate) fn workspace(n: usize) -> Workspace {
        let mut ws = Workspace::default();
        let rgb = vec![0u8; WORK_SIZE.pixels() * 3];
        for _ in 0..n {
            let source = PairSource::Upload {
                view_a: "a.png".into(),
                view_b: "b.png".into(),
                views: None,
            };
            ws.add(LabeledPair::new(
                ws.next_id(),
                source,
                rgb.clone(),
                rgb.clone(),
            ));
        }
        ws
    }

    /// One stroke of `tool` from `from` to `to`, radius `r`, on the current pair's `view`.
    fn stroke(ws: &mut Workspace, view: View, tool: Tool, [from, to]: [[f64; 2]; 2], r: f64) {
        ws.begin_stroke(view, None);
        ws.stroke_to(from, to, r, tool);
        ws.end_stroke();
    }

    /// A brush stroke.
    fn brush(ws: &mut Workspace, view: View, from: [f64; 2], to: [f64; 2], r: f64) {
        stroke(ws, view, Tool::Brush, [from, to], r);
    }

    /// An eraser stroke.
    fn erase(ws: &mut Workspace, view: View, from: [f64; 2], to: [f64; 2], r: f64) {
        stroke(ws, view, Tool::Eraser, [from, to], r);
    }
    #[test]
    fn a_correction_starts_from_h_nets_mask_and_undoes_with_it() {
        let mut ws = workspace(1);
        let size = WORK_SIZE.pixels();
        let mut hnet = vec![0u8; size];
        // The first three rows.
        let rows = WORK_SIZE.width * 3;
        hnet[..rows].fill(255);
        // The first stroke on an empty view starts from H-Net's mask, and adds to it.
        ws.begin_stroke(View::A, Some(hnet.clone()));
        ws.stroke_to([50.0, 100.0], [60.0, 100.0], 3.0, Tool::Brush);
        ws.end_stroke();
        let painted = ws.current().unwrap().mask(View::A).to_vec();
        assert!(painted[..rows].iter().all(|&v| v == 255));
        assert!(painted.iter().filter(|&&v| v > 0).count() > rows);
        // One undo step takes both away.
        ws.undo();
        assert!(ws.current().unwrap().mask(View::A).iter().all(|&v| v == 0));
        assert!(!ws.current().unwrap().masks_labeled);
        // A view that already holds a label is not overwritten.
        ws.redo();
        let mut other = vec![0u8; size];
        other[size - 10..].fill(255);
        ws.begin_stroke(View::A, Some(other));
        ws.end_stroke();
        assert_eq!(ws.current().unwrap().mask(View::A), painted.as_slice());
    }

    #[test]
    fn strokes_undo_and_redo_one_at_a_time() {
        let mut ws = workspace(1);
        brush(&mut ws, View::A, [10.0, 10.0], [40.0, 10.0], 3.0);
        let painted = ws.current().unwrap().mask_a.clone();
        // A 30 px long, 6 px wide stroke with round ends.
        let n = painted.iter().filter(|&&m| m == 255).count();
        assert!((180..=230).contains(&n), "{n}");
        assert!(ws.current().unwrap().masks_labeled);
        erase(&mut ws, View::A, [20.0, 10.0], [20.0, 10.0], 5.0);
        assert!(ws.current().unwrap().labeled_pixels(View::A) < n);

        assert!(ws.undo().is_some());
        assert_eq!(ws.current().unwrap().mask_a, painted);
        assert!(ws.undo().is_some());
        assert!(ws.current().unwrap().mask_a.iter().all(|&m| m == 0));
        assert!(!ws.current().unwrap().masks_labeled);
        assert!(ws.undo().is_none());
        assert!(ws.redo().is_some());
        assert_eq!(ws.current().unwrap().mask_a, painted);
        // A new stroke clears what could be redone.
        brush(&mut ws, View::B, [5.0, 5.0], [6.0, 6.0], 2.0);
        assert!(ws.redo().is_none());
        assert_eq!(ws.can_undo_redo(), (true, false));
    }

    #[test]
    fn a_stroke_that_changes_nothing_is_no_undo_step() {
        let mut ws = workspace(1);
        erase(&mut ws, View::A, [10.0, 10.0], [12.0, 10.0], 2.0);
        assert_eq!(ws.can_undo_redo(), (false, false));
    }

    #[test]
    fn pre_labels_are_one_undo_step_for_both_views() {
        let mut ws = workspace(1);
        let full = vec![255u8; WORK_SIZE.pixels()];
        assert!(ws.set_masks([full.clone(), full.clone()]).is_some());
        assert_eq!(ws.current().unwrap().mask_b, full);
        ws.undo();
        let p = ws.current().unwrap();
        assert!(p.mask_a.iter().chain(&p.mask_b).all(|&m| m == 0));
        assert_eq!(ws.can_undo_redo(), (false, true));
    }

    #[test]
    fn painting_at_the_border_stays_inside() {
        let size = ImageSize::square(16);
        let mut mask = vec![0u8; size.pixels()];
        assert!(paint_disc(&mut mask, size, 0.0, 15.9, 3.0, Tool::Brush));
        assert!(paint_disc(&mut mask, size, 15.9, 0.0, 3.0, Tool::Brush));
        assert!(!paint_disc(&mut mask, size, -20.0, -20.0, 3.0, Tool::Brush));
        assert!(!paint_disc(&mut mask, size, 40.0, 8.0, 3.0, Tool::Brush));
        assert_eq!(mask[15 * 16], 255);
        assert_eq!(mask[15], 255);
        // A wide mask: `width` pixels per row, `height` rows.
        let size = ImageSize::new(16, 4);
        let mut mask = vec![0u8; size.pixels()];
        assert!(paint_disc(&mut mask, size, 15.9, 3.9, 1.0, Tool::Brush));
        assert_eq!(mask[3 * 16 + 15], 255);
        assert!(!paint_disc(&mut mask, size, 8.0, 8.0, 1.0, Tool::Brush));
    }

    #[test]
    fn ids_do_not_repeat_after_removal() {
        let mut ws = workspace(2);
        assert_eq!(ws.pairs[1].id, "pair-0002");
        ws.select(0);
        assert_eq!(ws.remove_current().unwrap().pair.id, "pair-0001");
        assert_eq!(ws.next_id(), "pair-0003");
        ws.step(1);
        assert_eq!(ws.current, Some(0));
    }

    #[test]
    fn a_deleted_pair_comes_back_where_it_was_with_its_history() {
        let mut ws = workspace(3);
        ws.select(1);
        brush(&mut ws, View::A, [10.0, 10.0], [60.0, 10.0], 3.0);
        ws.set_force(
            "pair-0002",
            Some((TipForce::new(0.1, 0.2, -0.1), LabelOrigin::Typed)),
        );
        let before = ws.pairs.clone();
        let removed = ws.remove_current().unwrap();
        assert_eq!(ws.pairs.len(), 2);
        assert_eq!(ws.can_undo_redo(), (false, false));
        assert_eq!(ws.restore(removed.clone()).as_deref(), Some("pair-0002"));
        assert_eq!(ws.pairs, before);
        assert_eq!(ws.current, Some(1));
        // Its stroke can still be undone.
        assert_eq!(ws.undo().as_deref(), Some("pair-0002"));
        assert_eq!(ws.pairs[1].labeled_pixels(View::A), 0);
        assert_eq!(ws.redo().as_deref(), Some("pair-0002"));
        // Edits of the restored pair go back where they were in time: here a newer stroke on
        // pair-0001 is undone first.
        ws.select(0);
        brush(&mut ws, View::A, [5.0, 5.0], [20.0, 5.0], 2.0);
        ws.select(1);
        let again = ws.remove_current().unwrap();
        ws.restore(again);
        assert_eq!(ws.undo().as_deref(), Some("pair-0001"));
        assert_eq!(ws.undo().as_deref(), Some("pair-0002"));
        // A restore never replaces a pair that holds the id.
        assert_eq!(ws.restore(removed), None);
    }

    #[test]
    fn typed_newtons_accept_ordinary_typing_and_name_the_problem() {
        assert_eq!(parse_newtons("Fx", "0.12"), Ok(0.12));
        assert_eq!(parse_newtons("Fx", " -0.05 "), Ok(-0.05));
        assert_eq!(parse_newtons("Fx", "0,2"), Ok(0.2));
        assert_eq!(parse_newtons("Fx", ".5"), Ok(0.5));
        assert_eq!(
            parse_newtons("Fy", "").unwrap_err().to_string(),
            "Fy is empty: enter a number of newtons"
        );
        assert_eq!(
            parse_newtons("Fz", "abc").unwrap_err().to_string(),
            "Fz is `abc`, not a number of newtons"
        );
        assert!(parse_newtons("Fz", "inf").is_err());
        assert!(implausible_tip_force(TipForce::new(5.0, 0.0, 0.0)).is_some());
        assert!(implausible_tip_force(TipForce::new(0.12, -0.05, 0.2)).is_none());
    }

    #[test]
    fn force_labels_come_from_csv_with_clear_errors() {
        let labels =
            parse_force_labels("f.csv", b"id,fx,fy,fz\npair-0001, 0.1,-0.2,0.05\n").unwrap();
        assert_eq!(
            labels,
            vec![(
                "pair-0001".to_string(),
                TipForce::new(0.1, -0.2, 0.05),
                LabelOrigin::Imported
            )]
        );
        // A table that says where its labels came from keeps it.
        let measured = b"id,fx,fy,fz,label_origin\np1,0.1,0,0,measured\n";
        assert_eq!(
            parse_force_labels("s.csv", measured).unwrap()[0].2,
            LabelOrigin::Measured
        );
        // A dataset's manifest (extra columns, other order) works too.
        let manifest = b"id,split,fx,fy,fz,source\np1,train,0.1,0.2,0.3,x\n";
        assert_eq!(
            parse_force_labels("m.csv", manifest).unwrap()[0].1,
            TipForce::new(0.1, 0.2, 0.3)
        );

        let err = parse_force_labels("f.csv", b"id,fx,fy,fz\np1,0,0,0\np2,0,NaN,0\n").unwrap_err();
        assert_eq!(err.table.line, Some(3));
        assert!(err.to_string().contains("f.csv, line 3"), "{err}");
        assert!(err.table.problem.contains("fy of `p2`"), "{err}");
        let err = parse_force_labels("g.csv", b"name,fx,fy,fz\n").unwrap_err();
        assert!(err.table.problem.contains("`id`"), "{err}");
        assert!(parse_force_labels("e.csv", b"id,fx,fy,fz\n").is_err());
        // A value far outside a catheter's range is refused with its line.
        let err =
            parse_force_labels("big.csv", b"id,fx,fy,fz\np1,0.1,0,0\np2,1e6,0,0\n").unwrap_err();
        assert_eq!(err.table.line, Some(3));
        assert!(
            err.table
                .problem
                .starts_with("the force of `p2` is refused: |F| = 1000000.000 N"),
            "{err}"
        );

        let mut ws = workspace(1);
        let (applied, unknown) = ws.apply_force_labels(&[
            (
                "pair-0001".into(),
                TipForce::new(0.1, 0.0, 0.0),
                LabelOrigin::Measured,
            ),
            (
                "pair-0099".into(),
                TipForce::new(0.0, 0.0, 0.0),
                LabelOrigin::Imported,
            ),
        ]);
        assert_eq!((applied, unknown), (1, vec!["pair-0099".to_string()]));
        assert_eq!(ws.pairs[0].force_n, Some(TipForce::new(0.1, 0.0, 0.0)));
        assert_eq!(ws.pairs[0].force_origin, LabelOrigin::Measured);
    }

    #[test]
    fn a_pair_is_complete_only_when_both_masks_hold_a_catheter_or_are_marked_empty() {
        let mut ws = workspace(1);
        let id = ws.current().unwrap().id.clone();
        ws.set_force(
            &id,
            Some((TipForce::new(0.1, 0.0, 0.0), LabelOrigin::Typed)),
        );
        assert_eq!(
            ws.current().unwrap().incomplete_because(),
            Some("masks not labeled")
        );
        // Only view A painted: view B's empty mask is a label not made yet.
        brush(&mut ws, View::A, [10.0, 10.0], [60.0, 10.0], 3.0);
        let pair = ws.current().unwrap();
        assert!(pair.masks_labeled && !pair.masks_complete() && !pair.is_complete());
        assert!(
            pair.incomplete_because()
                .unwrap()
                .starts_with("view B's mask is empty"),
            "{:?}",
            pair.incomplete_because()
        );
        // Marked as showing no catheter on purpose, it is a label.
        assert!(ws.mark_no_catheter(&id, View::B, true));
        assert!(ws.current().unwrap().is_complete());
        ws.mark_no_catheter(&id, View::B, false);
        brush(&mut ws, View::B, [10.0, 20.0], [60.0, 20.0], 3.0);
        assert!(ws.current().unwrap().is_complete());
        // Erased again to nothing: incomplete again.
        erase(&mut ws, View::A, [10.0, 10.0], [60.0, 10.0], 6.0);
        assert!(
            ws.current()
                .unwrap()
                .incomplete_because()
                .unwrap()
                .starts_with("view A's mask is empty")
        );
        // Cleared, the label's origin goes with it.
        ws.set_force(&id, None);
        assert_eq!(ws.current().unwrap().force_origin, LabelOrigin::Unrecorded);
    }
}

// Property tests (issue #13, docs/reliability.md): force-label files and typed forces give
// labels or an error, never a panic or a non-finite label, and labels round-trip exactly.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod properties {
    use super::*;
    use crate::force_label::{implausible_tip_force, parse_force_labels, parse_newtons};
    use crate::imaging::properties::cases;
    use proptest::prelude::*;

    /// A force component a label may hold: plausible, any `f32` bits in the range.
    fn component() -> impl Strategy<Value = f32> {
        prop_oneof![-0.5f32..0.5, Just(0.0), Just(-0.0), 1e-30f32..1e-20]
    }

    proptest! {
        #![proptest_config(cases(256))]

        #[test]
        fn any_bytes_are_labels_or_an_error(
            header in prop_oneof![Just(""), Just("id,fx,fy,fz\n"), Just("ID, FZ ,fy,note,Fx\n")],
            bytes in proptest::collection::vec(any::<u8>(), 0..256),
        ) {
            let bytes = [header.as_bytes(), &bytes].concat();
            if let Ok(labels) = parse_force_labels("f.csv", &bytes) {
                prop_assert!(!labels.is_empty());
                for (id, force, _) in labels {
                    prop_assert!(!id.is_empty());
                    prop_assert!(force.is_finite(), "{:?}", force);
                    prop_assert!(implausible_tip_force(force).is_none());
                }
            }
        }

        #[test]
        fn typed_forces_are_finite_or_an_error(text in prop_oneof![
            "\\PC{0,16}",
            any::<f64>().prop_map(|v| v.to_string()),
            any::<f32>().prop_map(|v| v.to_string()),
        ]) {
            if let Ok(v) = parse_newtons("Fx", &text) {
                prop_assert!(v.is_finite(), "`{}` read as {}", text, v);
            }
        }

        #[test]
        fn force_labels_round_trip_exactly(
            labels in proptest::collection::btree_map(
                "[a-zA-Z0-9_.-]{1,12}",
                [component(), component(), component()],
                1..12,
            ),
            comma_decimals in any::<bool>(),
        ) {
            let mut csv = String::from("id,fx,fy,fz\n");
            for (id, [x, y, z]) in &labels {
                if comma_decimals {
                    // As a spreadsheet in a comma-decimal locale writes them.
                    let c = |v: f32| format!("\"{}\"", v.to_string().replace('.', ","));
                    csv.push_str(&format!("{id},{},{},{}\n", c(*x), c(*y), c(*z)));
                } else {
                    csv.push_str(&format!("{id},{x},{y},{z}\n"));
                }
            }
            let read = parse_force_labels("f.csv", csv.as_bytes()).unwrap();
            prop_assert_eq!(read.len(), labels.len());
            for ((id, force, _), (want_id, want)) in read.iter().zip(&labels) {
                prop_assert_eq!(id, want_id);
                prop_assert_eq!(force.newtons().map(f32::to_bits), want.map(f32::to_bits), "{}", csv);
            }
        }

        /// What the page keeps in IndexedDB beside the images (storage.rs' record, wasm-only,
        /// holds these fields): a pair's metadata round-trips exactly through JSON.
        #[test]
        fn pair_metadata_round_trips_exactly(
            id in "[a-zA-Z0-9_.-]{1,16}",
            names in ("\\PC{0,20}", "\\PC{0,20}"),
            twin in proptest::option::of(([component(), component(), component()], [any::<f64>(), any::<f64>(), any::<f64>()])),
            force in proptest::option::of([component(), component(), component()]),
            split in proptest::option::of(prop_oneof![Just(Split::Train), Just(Split::Val), Just(Split::Test)]),
            masks_labeled in any::<bool>(),
        ) {
            let source = match twin {
                Some((true_force_n, tip_mm)) if tip_mm.iter().all(|v| v.is_finite()) => PairSource::Twin {
                    true_force_n: TipForce::from_newtons(true_force_n),
                    tip_mm,
                    views: Biplane::cardiac(WORK_SIZE),
                    settings: serde_json::json!({"force_n": true_force_n, "seed": 3}),
                },
                _ => PairSource::Upload { view_a: names.0, view_b: names.1, views: None },
            };
            let pair = LabeledPair {
                id,
                source,
                view_a: vec![1, 2, 3],
                view_b: vec![4, 5, 6],
                mask_a: vec![0],
                mask_b: vec![255],
                masks_labeled,
                force_n: force.map(TipForce::from_newtons),
                force_origin: LabelOrigin::Estimate {
                    weights: "w.bpk".into(),
                    estimator: "combined".into(),
                },
                no_catheter: [masks_labeled, false],
                split,
            };
            let json = serde_json::to_string(&pair).unwrap();
            let back: LabeledPair = serde_json::from_str(&json).unwrap();
            prop_assert_eq!(back, pair);
        }
    }
}
