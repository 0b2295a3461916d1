//! The catheter's centreline in one view, with sub-pixel precision, from its mask.
//!
//! Pixel convention (the same as [`crate::simulator::render`] and [`crate::simulator::carm::CArm::project`]): pixel
//! `(x, y)` of a row-major `width x height` mask covers `[x, x+1) x [y, y+1)` and its value sits at
//! its centre `(x + 0.5, y + 0.5)`; points are `[u, v]` = `[column, row]` in pixels.
//!
//! The method:
//!
//! 1. The mask is cut at half coverage; its 8-connected blobs are found. Specks smaller than
//!    [`CentrelineSettings::min_blob_px`] (and than [`CentrelineSettings::min_blob_fraction`]
//!    of the largest blob) are ignored. The largest blob is the catheter. Another blob is set
//!    aside (and its pixels no longer read) when it lies beside the catheter: the catheter
//!    enters from the border, the other blob is smaller than
//!    [`CentrelineSettings::set_aside_fraction`] of it, and it does not lie beyond the tip, where
//!    it could be the catheter's own continuation ([`CentrelineSettings::beyond_tip_px`]). Such
//!    blobs are other devices or structures of the background read as catheter (a chest
//!    radiograph's edges). Any other blob left is an error, not a guess.
//! 2. **Ordering.** The proximal end is where the catheter leaves the image: the blob's pixels on
//!    the image border (if it touches the border in several places, the contact nearest to
//!    [`CentrelineSettings::proximal_hint_px`] or else the one with the most coverage). A blob
//!    that does not touch the border is ordered from its end nearer to the border (the catheter
//!    comes in from outside the field of view). The tip is the blob pixel farthest from the
//!    proximal end along paths inside the blob (Dijkstra, 8-neighbours), and the pixel path
//!    between them gives the first, staircase, centreline.
//! 3. **Sub-pixel refinement.** The path is smoothed and resampled at 1 px; then, three times,
//!    every point moves to the intensity-weighted centroid of the mask's values along the local
//!    normal (bilinear samples every 0.25 px, three parallel profiles half a pixel apart). For
//!    the exact anti-aliased masks of the twin, whose coverage falls linearly from 1 to 0 over one
//!    pixel across the outline, this centroid is the projected axis. The integral of a profile
//!    is the shaft's width.
//! 4. **Tip.** The mask ends with the tube's round cap, a half disc of half the shaft's width
//!    around the tip's centre: the centreline is cut (or extended) to the point where the mask's
//!    area still ahead of it is that half disc's (an area is robust to a ragged outline).
//! 5. **Check.** Every pixel of the blob must lie on the tube around the centreline (within half
//!    a width plus 1.5 px), and the tube's width may not grow by more than half anywhere: where
//!    the catheter crosses or overlaps itself in the view (a loop, a hairpin, a tip curled back
//!    over the shaft), or the mask has a branch, the centreline cannot be the catheter's, and
//!    that is an error ([`CentrelineError::NotATube`]) rather than a wrong curve.
//! 6. The result is resampled at equal arc-length steps of at most
//!    [`CentrelineSettings::spacing_px`].
//!
//! Pure computation (no threads, no files): it runs in the browser as well.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use hnet_units::mask::{is_catheter, is_catheter_label};
use serde::{Deserialize, Serialize};

/// A mask's values: 8-bit coverage (255 = catheter) or soft values in `[0, 1]` (probabilities or
/// coverage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MaskValues<'a> {
    /// 8-bit coverage, 255 = fully catheter (the dataset's mask PNGs, the twin's masks).
    Coverage8(&'a [u8]),
    /// Soft values in `[0, 1]` (a network's probabilities); values outside are clamped, NaN is 0.
    Soft(&'a [f32]),
}

/// A row-major mask of one view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mask<'a> {
    /// Width in pixels (columns, `u`).
    pub width: usize,
    /// Height in pixels (rows, `v`).
    pub height: usize,
    /// `width·height` values.
    pub values: MaskValues<'a>,
}

impl<'a> Mask<'a> {
    /// An 8-bit coverage mask.
    pub fn coverage8(width: usize, height: usize, values: &'a [u8]) -> Self {
        Self {
            width,
            height,
            values: MaskValues::Coverage8(values),
        }
    }

    /// A soft mask with values in `[0, 1]`.
    pub fn soft(width: usize, height: usize, values: &'a [f32]) -> Self {
        Self {
            width,
            height,
            values: MaskValues::Soft(values),
        }
    }

    fn len(&self) -> usize {
        match self.values {
            MaskValues::Coverage8(v) => v.len(),
            MaskValues::Soft(v) => v.len(),
        }
    }

    /// The share of its pixels at half coverage or more (the mask threshold everywhere,
    /// [`hnet_units::mask`]), 0-1.
    pub fn share_at_half(&self) -> f64 {
        let found = match self.values {
            MaskValues::Coverage8(v) => v.iter().filter(|&&b| is_catheter_label(b)).count(),
            MaskValues::Soft(v) => v.iter().filter(|&&x| is_catheter(x)).count(),
        };
        found as f64 / self.len().max(1) as f64
    }

    fn to_f32(self) -> Vec<f32> {
        match self.values {
            MaskValues::Coverage8(v) => v.iter().map(|&b| f32::from(b) / 255.0).collect(),
            MaskValues::Soft(v) => v
                .iter()
                .map(|&x| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) })
                .collect(),
        }
    }
}

/// How a centreline is extracted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CentrelineSettings {
    /// Largest arc-length step between the returned points, pixels.
    pub spacing_px: f64,
    /// Blobs smaller than this many pixels are specks and ignored.
    pub min_blob_px: usize,
    /// Blobs smaller than this fraction of the largest one are specks and ignored.
    pub min_blob_fraction: f64,
    /// A blob beside the catheter is set aside only when smaller than this fraction of the
    /// catheter's blob; a larger one leaves the view ambiguous.
    #[serde(default = "default_set_aside_fraction")]
    pub set_aside_fraction: f64,
    /// A blob lies beyond the catheter's tip, and may be its continuation, when its nearest
    /// pixel to the tip is no more than this many pixels farther than its nearest to the
    /// catheter.
    #[serde(default = "default_beyond_tip_px")]
    pub beyond_tip_px: f64,
    /// Shortest acceptable centreline, pixels.
    pub min_length_px: f64,
    /// If given, the end of the catheter nearest to this point `[u, v]` is the proximal one
    /// (for a catheter that touches the border twice, or not at all).
    pub proximal_hint_px: Option<[f64; 2]>,
    /// Most mask area allowed off the tube around the centreline (farther than half a width
    /// plus 1.5 px from it), in squared shaft widths.
    pub max_off_tube_widths2: f64,
    /// Largest ratio allowed between the mask's width in a place (median over 7 px) and along
    /// most of it (its lower quartile).
    pub max_width_ratio: f64,
}

impl Default for CentrelineSettings {
    fn default() -> Self {
        Self {
            spacing_px: 1.0,
            min_blob_px: 8,
            min_blob_fraction: 0.1,
            set_aside_fraction: default_set_aside_fraction(),
            beyond_tip_px: default_beyond_tip_px(),
            min_length_px: 10.0,
            proximal_hint_px: None,
            max_off_tube_widths2: 2.0,
            max_width_ratio: 1.5,
        }
    }
}

/// Half: a blob of half the catheter's pixels or more is as likely a second device in view.
fn default_set_aside_fraction() -> f64 {
    0.5
}

/// 4 px: the pieces of a catheter broken where the mask dips below half coverage (seen on
/// the chest-radiograph bench set) start at the piece before's tip, within a pixel or two.
fn default_beyond_tip_px() -> f64 {
    4.0
}

/// A view's centreline, ordered from the proximal end to the tip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Centreline {
    /// Points `[u, v]` in pixels (pixel centres at `+0.5`), equally spaced along the curve.
    pub points_px: Vec<[f64; 2]>,
    /// Arc length of each point from the first, pixels.
    pub arc_px: Vec<f64>,
    /// The shaft's width (median over the curve), pixels.
    pub width_px: f64,
    /// Whether the proximal end is on the image border (the catheter enters the image there).
    pub proximal_at_border: bool,
    /// Whether the distal end is on the image border: the tip is outside the image and the last
    /// point is not the tip.
    pub tip_at_border: bool,
    /// Sizes in pixels of the blobs set aside beside the catheter (largest first; empty when
    /// the mask was one blob).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub set_aside_px: Vec<usize>,
}

impl Centreline {
    /// Length along the curve, pixels.
    pub fn length_px(&self) -> f64 {
        self.arc_px.last().copied().unwrap_or(0.0)
    }

    /// The last point: the tip, unless [`Centreline::tip_at_border`].
    pub fn tip_px(&self) -> [f64; 2] {
        *self.points_px.last().expect("a centreline has points")
    }
}

mod trace;
pub(crate) use trace::arc_lengths;
use trace::*;

/// Why a mask gives no centreline.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CentrelineError {
    /// The values do not fill `width x height`.
    #[error("view {view}: the mask is {width}x{height} but has {values} values")]
    WrongSize {
        /// The view's name.
        view: String,
        /// Width given.
        width: usize,
        /// Height given.
        height: usize,
        /// Values given.
        values: usize,
    },
    /// Nothing in the mask reaches half coverage.
    #[error("view {view}: the mask is empty (no pixel reaches half coverage)")]
    Empty {
        /// The view's name.
        view: String,
    },
    /// More than one blob of significant size.
    #[error(
        "view {view}: the mask has {} separate blobs of {} pixels, expected one catheter",
        sizes.len(),
        sizes.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")
    )]
    SeveralBlobs {
        /// The view's name.
        view: String,
        /// Sizes of the significant blobs in pixels, largest first.
        sizes: Vec<usize>,
    },
    /// The mask is not one tube of constant width around its centreline.
    #[error(
        "view {view}: the mask is not one catheter seen once: {misfit}; the catheter crosses or overlaps itself in this view, or the mask has a branch"
    )]
    NotATube {
        /// The view's name.
        view: String,
        /// What does not fit.
        misfit: TubeMisfit,
        /// The blob's size, its centreline's length and its shaft's width.
        blob: BlobMeasure,
    },
    /// The centreline is shorter than [`CentrelineSettings::min_length_px`].
    #[error(
        "view {view}: the catheter's centreline is only {length_px:.1} px long (at least {min_px:.1} px needed)"
    )]
    TooShort {
        /// The view's name.
        view: String,
        /// Its length, pixels.
        length_px: f64,
        /// The least accepted, pixels.
        min_px: f64,
    },
}

/// How a blob fails to be one clean tube around its centreline
/// ([`CentrelineError::NotATube`]).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TubeMisfit {
    /// Too much of the mask lies off the tube around the centreline (farther than half a width
    /// plus 1.5 px from it).
    #[error(
        "{off_px:.0} px of it lie off the centreline's tube (at most {allowed_px:.0} px allowed)"
    )]
    OffTube {
        /// Coverage off the tube, pixels.
        off_px: f64,
        /// The most allowed ([`CentrelineSettings::max_off_tube_widths2`] squared widths),
        /// pixels.
        allowed_px: f64,
    },
    /// The mask is much wider in places than along most of its length (two stretches side by
    /// side: a hairpin in the view).
    #[error(
        "it is {ratio:.1} times as wide in places as along most of its length (at most {allowed:.1} allowed)"
    )]
    Wider {
        /// Widest place (median over 7 px) over the lower quartile of the widths.
        ratio: f64,
        /// The most allowed ([`CentrelineSettings::max_width_ratio`]).
        allowed: f64,
    },
}

/// The size and shape of the blob taken for the catheter, in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlobMeasure {
    /// Its pixels at half coverage or more.
    pub pixels: usize,
    /// Its coverage summed, pixels.
    pub area_px: f64,
    /// Its centreline's length, pixels.
    pub length_px: f64,
    /// Its shaft's width, the median across the centreline, pixels.
    pub width_px: f64,
}

impl CentrelineError {
    /// A short name of the check that failed (`empty`, `several blobs`, `not a tube`, `too
    /// short`, `wrong size`), for counts.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::WrongSize { .. } => "wrong size",
            Self::Empty { .. } => "empty",
            Self::SeveralBlobs { .. } => "several blobs",
            Self::NotATube { .. } => "not a tube",
            Self::TooShort { .. } => "too short",
        }
    }
}

/// The mask's values with bilinear sampling at continuous pixel coordinates.
struct Field<'a> {
    width: usize,
    height: usize,
    values: &'a [f32],
}

impl Field<'_> {
    /// Bilinear value at `(u, v)` (pixel centres at `+0.5`), clamped to the border pixels: the
    /// shaft is taken to continue beyond the image as it enters it.
    fn sample(&self, u: f64, v: f64) -> f64 {
        let fx = (u - 0.5).clamp(0.0, (self.width - 1) as f64);
        let fy = (v - 0.5).clamp(0.0, (self.height - 1) as f64);
        // Truncation is the floor here: both are clamped to be non-negative.
        let (x0, y0) = (fx as usize, fy as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        let at = |x: usize, y: usize| f64::from(self.values[y * self.width + x]);
        let top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
        let bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
        top * (1.0 - ty) + bottom * ty
    }
}

const NEIGHBOURS: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// The 8-neighbours of pixel `i` (row-major) that lie inside a `width` x `height` image, each
/// with whether it is a diagonal one.
fn neighbours(i: usize, width: usize, height: usize) -> impl Iterator<Item = (usize, bool)> {
    let (x, y) = ((i % width) as isize, (i / width) as isize);
    NEIGHBOURS.into_iter().filter_map(move |(dx, dy)| {
        let (nx, ny) = (x + dx, y + dy);
        (nx >= 0 && ny >= 0 && nx < width as isize && ny < height as isize)
            .then(|| (ny as usize * width + nx as usize, dx != 0 && dy != 0))
    })
}

/// Least share of a view's pixels that must reach half coverage for the view to show a catheter
/// ([`catheter_seen`]). Measured with `hnet study no-catheter` on the bundled model
/// (docs/results.md, "No catheter, no force").
pub const MIN_CATHETER_SHARE: f64 = 0.0025;

/// Most share of a view's pixels a catheter can cover. A 7 Fr catheter's shadow laid across the
/// whole diagonal of a 94 mm cardiac field covers under 4 % of it (the bench set's views: 1.6 %
/// median); 10 % refuses a view painted catheter over a large part (the network paints 16 % of
/// a black image).
pub const MAX_CATHETER_SHARE: f64 = 0.1;

/// Why a view shows no catheter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoCatheter {
    /// Too few pixels read as catheter.
    #[error(
        "view {view}: no catheter found ({:.2} % of the pixels read as catheter, at least {:.2} % \
         needed)",
        share * 100.0,
        MIN_CATHETER_SHARE * 100.0
    )]
    TooFewPixels {
        /// The view's name.
        view: String,
        /// Share of its pixels at half coverage or more, 0-1.
        share: f64,
    },
    /// Far more pixels read as catheter than a catheter can cover.
    #[error(
        "view {view}: no catheter found ({:.0} % of the pixels read as catheter, more than a \
         catheter covers)",
        share * 100.0
    )]
    TooManyPixels {
        /// The view's name.
        view: String,
        /// Share of its pixels at half coverage or more, 0-1.
        share: f64,
    },
    /// The pixels do not form one catheter (several blobs, too short).
    #[error("no catheter found")]
    NotACatheter(#[source] CentrelineError),
    /// The largest blob is not one clean tube, and most of the pixels read as catheter lie
    /// outside it: a texture painted over the view, not a catheter crossing itself.
    #[error(
        "view {view}: no catheter found (the pixels read as catheter are scattered: the largest \
         blob, not one clean tube, holds {:.0} % of them, at least {:.0} % needed)",
        in_blob * 100.0,
        MIN_TANGLED_BLOB_SHARE * 100.0
    )]
    Scattered {
        /// The view's name.
        view: String,
        /// Share of the pixels read as catheter that lie in the largest blob, 0-1.
        in_blob: f64,
    },
}

/// Least share of a view's pixels read as catheter that must lie in its largest blob when that
/// blob is not one clean tube ([`CatheterSeen::Tangled`]). A catheter crossing itself in the
/// view is one blob with at most a few smaller ones beside it (each under half its size,
/// [`CentrelineSettings::set_aside_fraction`]); the blobs a network paints on a texture it was
/// never shown are many. Measured with `hnet study no-catheter` (docs/results.md, "No catheter,
/// no force"): on uniform noise the outline-term weights' largest blob held 24-46 % of the
/// pixels they read as catheter, a rendered loop 100 %.
pub const MIN_TANGLED_BLOB_SHARE: f64 = 0.6;

/// Whether `mask` (view `view`) shows a catheter, or why not: at least [`MIN_CATHETER_SHARE`]
/// and at most [`MAX_CATHETER_SHARE`] of its pixels at half coverage or more, in one blob long
/// enough for a catheter (smaller blobs beside it set aside, as [`extract_centreline`] does).
/// A blob that is not a clean tube (a catheter crossing itself, or a mask wider in places) still
/// counts, as a catheter the physics estimate cannot fit, when it holds most of the pixels read
/// as catheter ([`MIN_TANGLED_BLOB_SHARE`]). The one rule that withholds a force from a view
/// without a catheter (the page, `hnet trace`; `hnet study no-catheter` measures it).
pub fn catheter_seen(
    mask: &Mask<'_>,
    view: &str,
    settings: &CentrelineSettings,
) -> Result<CatheterSeen, NoCatheter> {
    let share = mask.share_at_half();
    if share < MIN_CATHETER_SHARE {
        return Err(NoCatheter::TooFewPixels {
            view: view.into(),
            share,
        });
    }
    if share > MAX_CATHETER_SHARE {
        return Err(NoCatheter::TooManyPixels {
            view: view.into(),
            share,
        });
    }
    match extract_centreline(mask, view, settings) {
        Ok(_) => Ok(CatheterSeen::Tube),
        Err(CentrelineError::NotATube { misfit, blob, .. }) => {
            let read_px = share * (mask.width * mask.height) as f64;
            let in_blob = blob.pixels as f64 / read_px.max(1.0);
            if in_blob >= MIN_TANGLED_BLOB_SHARE {
                Ok(CatheterSeen::Tangled(misfit))
            } else {
                Err(NoCatheter::Scattered {
                    view: view.into(),
                    in_blob,
                })
            }
        }
        Err(other) => Err(NoCatheter::NotACatheter(other)),
    }
}

/// How a view shows its catheter ([`catheter_seen`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CatheterSeen {
    /// As one clean tube: its centreline can be read.
    Tube,
    /// As one blob that is not a clean tube but could be a catheter crossing or overlapping
    /// itself in the view: a catheter the physics estimate cannot fit.
    Tangled(TubeMisfit),
}

/// The catheter's centreline in view `view` of `mask`, in pixels, proximal end first (the
/// method: this module's doc), or why the mask holds no single catheter.
pub fn extract_centreline(
    mask: &Mask<'_>,
    view: &str,
    settings: &CentrelineSettings,
) -> Result<Centreline, CentrelineError> {
    let (width, height) = (mask.width, mask.height);
    if width == 0 || height == 0 || mask.len() != width * height {
        return Err(CentrelineError::WrongSize {
            view: view.into(),
            width,
            height,
            values: mask.len(),
        });
    }
    let mut values = mask.to_f32();
    let inside: Vec<bool> = values.iter().map(|&c| is_catheter(c)).collect();
    let CatheterBlob {
        pixels: blob,
        set_aside,
    } = catheter_blob(&inside, width, height, view, settings)?;
    // What was set aside is not the catheter's: the refinement must not read it.
    for &i in set_aside.iter().flatten() {
        values[i] = 0.0;
    }
    let field = Field {
        width,
        height,
        values: &values,
    };

    let on_border = |i: usize| {
        let (x, y) = (i % width, i / width);
        x == 0 || y == 0 || x == width - 1 || y == height - 1
    };
    let border_pixels: Vec<usize> = blob.iter().copied().filter(|&i| on_border(i)).collect();
    let centre_of = |i: usize| [(i % width) as f64 + 0.5, (i / width) as f64 + 0.5];
    let distance_to_border = |p: [f64; 2]| {
        p[0].min(width as f64 - p[0])
            .min(p[1])
            .min(height as f64 - p[1])
    };
    let near_hint = |hint: [f64; 2], p: [f64; 2]| (p[0] - hint[0]).hypot(p[1] - hint[1]);

    let mut in_blob = vec![false; width * height];
    for &i in &blob {
        in_blob[i] = true;
    }
    // The proximal sources and the tip.
    let (sources, proximal_at_border) = if border_pixels.is_empty() {
        let (first_far, _, _) = geodesic(&in_blob, width, height, &[blob[0]]);
        let (end_a, _, _) = geodesic(&in_blob, width, height, &[first_far]);
        let (end_b, _, _) = geodesic(&in_blob, width, height, &[end_a]);
        let score = |i: usize| match settings.proximal_hint_px {
            Some(hint) => near_hint(hint, centre_of(i)),
            None => distance_to_border(centre_of(i)),
        };
        let proximal = if score(end_b) < score(end_a) {
            end_b
        } else {
            end_a
        };
        (vec![proximal], false)
    } else {
        let runs = border_runs(&border_pixels, width);
        let best = match settings.proximal_hint_px {
            Some(hint) => runs.iter().min_by(|a, b| {
                let d = |run: &Vec<usize>| {
                    run.iter()
                        .map(|&i| near_hint(hint, centre_of(i)))
                        .fold(f64::INFINITY, f64::min)
                };
                d(a).total_cmp(&d(b))
            }),
            None => runs.iter().max_by(|a, b| {
                let c = |run: &Vec<usize>| run.iter().map(|&i| f64::from(values[i])).sum::<f64>();
                c(a).total_cmp(&c(b))
            }),
        };
        (best.expect("a border pixel makes a run").clone(), true)
    };
    let (tip, _, previous) = geodesic(&in_blob, width, height, &sources);
    let tip_at_border = on_border(tip) && proximal_at_border;
    let mut path = vec![centre_of(tip)];
    let mut at = tip;
    while let Some(p) = previous[at] {
        at = p;
        path.push(centre_of(at));
    }
    path.reverse();

    // A first estimate of the width: the blob's coverage over the path's length.
    let covered: f64 = blob.iter().map(|&i| f64::from(values[i])).sum();
    let rough_length = polyline_length(&path).max(1.0);
    let rough_width = (covered / rough_length).clamp(1.0, 50.0);

    let mut points = smooth(&path, (rough_width.round() as usize).max(2));
    points = resample(&points, 1.0);
    let mut widths = Vec::new();
    for iteration in 0..3 {
        let reach = if iteration == 0 {
            rough_width + 2.0
        } else {
            0.5 * median(&widths).max(1.0) + 2.0
        };
        let (refined, w) = refine(&field, &points, reach);
        widths = w;
        points = resample(&smooth(&refined, 1), 1.0);
    }
    let width_px = median(&widths).max(0.0);

    if !tip_at_border && points.len() >= 3 {
        // The width just before the tip's cap (perspective makes it differ along the catheter);
        // the profiles are one pixel apart.
        let n = widths.len();
        let near_tip = &widths[n.saturating_sub((width_px + 6.0) as usize)
            ..n.saturating_sub(width_px.ceil() as usize)];
        let local = median(near_tip);
        let radius = if near_tip.len() >= 3 && local > 0.0 {
            local
        } else {
            width_px
        } / 2.0;
        points = place_tip(&field, points, radius);
    }
    let length_px = polyline_length(&points);
    if length_px < settings.min_length_px || points.len() < 2 {
        return Err(CentrelineError::TooShort {
            view: view.into(),
            length_px,
            min_px: settings.min_length_px,
        });
    }
    // Every pixel of the blob must lie on the tube around the centreline; a catheter that
    // crosses or overlaps itself in this view, or a mask with a branch, leaves some off it.
    let reach = width_px / 2.0 + 1.5;
    let mut on_tube = vec![false; width * height];
    for p in resample(&points, 0.5) {
        let (x0, x1) = (
            (p[0] - reach - 0.5).floor().max(0.0) as usize,
            ((p[0] + reach - 0.5).ceil().max(0.0) as usize).min(width - 1),
        );
        let (y0, y1) = (
            (p[1] - reach - 0.5).floor().max(0.0) as usize,
            ((p[1] + reach - 0.5).ceil().max(0.0) as usize).min(height - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (du, dv) = (x as f64 + 0.5 - p[0], y as f64 + 0.5 - p[1]);
                if du * du + dv * dv <= reach * reach {
                    on_tube[y * width + x] = true;
                }
            }
        }
    }
    let off_tube: f64 = blob
        .iter()
        .filter(|&&i| !on_tube[i])
        .map(|&i| f64::from(values[i]))
        .sum();
    let allowed = settings.max_off_tube_widths2 * width_px * width_px;
    let not_a_tube = |misfit: TubeMisfit| CentrelineError::NotATube {
        view: view.into(),
        misfit,
        blob: BlobMeasure {
            pixels: blob.len(),
            area_px: covered,
            length_px,
            width_px,
        },
    };
    if off_tube > allowed {
        return Err(not_a_tube(TubeMisfit::OffTube {
            off_px: off_tube,
            allowed_px: allowed,
        }));
    }
    // Where two stretches lie side by side the mask is twice as wide (a hairpin in the view).
    let narrow = quantile(&widths, 0.25);
    let widest = widths.windows(7).map(median).fold(0.0f64, f64::max);
    if narrow > 0.0 && widest > settings.max_width_ratio * narrow {
        return Err(not_a_tube(TubeMisfit::Wider {
            ratio: widest / narrow,
            allowed: settings.max_width_ratio,
        }));
    }
    let points_px = resample(&points, settings.spacing_px.max(1e-3));
    let arc_px = arc_lengths(&points_px);
    Ok(Centreline {
        points_px,
        arc_px,
        width_px,
        proximal_at_border,
        tip_at_border,
        set_aside_px: set_aside.iter().map(Vec::len).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hnet_units::ImageSize;
    use std::ops::Range;

    use crate::simulator::carm::CArm;
    use crate::simulator::catheter::CatheterDesign;
    use crate::simulator::raster::to_byte;
    use crate::simulator::render::{PROXIMAL_SHAFT_MM, rasterize_catheter};
    use crate::simulator::rod::{RodBase, RodConfig, RodShape, solve};
    use crate::vec3::{Mat3, Vec3};

    /// Sets the pixels `xs` × `ys` of a mask `width` pixels wide to `value`.
    fn fill<T: Copy>(mask: &mut [T], width: usize, xs: Range<usize>, ys: Range<usize>, value: T) {
        for y in ys {
            mask[y * width + xs.start..y * width + xs.end].fill(value);
        }
    }

    /// The centreline of view `view`'s `w` x `h` byte mask, with the default settings.
    fn centreline8(
        w: usize,
        h: usize,
        mask: &[u8],
        view: &str,
    ) -> Result<Centreline, CentrelineError> {
        extract_centreline(&Mask::coverage8(w, h, mask), view, &Default::default())
    }

    /// Distance from `p` to the polyline `line`.
    fn distance_to(line: &[[f64; 2]], p: [f64; 2]) -> f64 {
        line.windows(2)
            .map(|w| {
                let (a, b) = (w[0], w[1]);
                let d = [b[0] - a[0], b[1] - a[1]];
                let len2 = d[0] * d[0] + d[1] * d[1];
                let t = if len2 > 0.0 {
                    (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The projected true centreline: the proximal shaft and the flexible section.
    fn projected(shape: &RodShape, view: &CArm) -> Vec<[f64; 2]> {
        let mut points = vec![shape.points_mm[0] - shape.tangents[0] * PROXIMAL_SHAFT_MM];
        points.extend_from_slice(&shape.points_mm);
        points
            .iter()
            .map(|p| {
                let q = view.project(*p);
                [q.u, q.v]
            })
            .collect()
    }

    fn bent_catheter(force: Vec3) -> RodShape {
        let config = RodConfig {
            precurvature_per_mm: [1.0 / 60.0, 0.0],
            steps: 100,
            ..RodConfig::default()
        };
        let base = RodBase {
            position_mm: Vec3::new(2.0, 1.0, -35.0),
            orientation: Mat3::rotation(Vec3::Z, 0.6),
        };
        solve(&config, &base, force).unwrap()
    }

    fn mask_of(shape: &RodShape, view: &CArm) -> Vec<u8> {
        rasterize_catheter(shape, 2.33, &CatheterDesign::default(), view)
            .coverage
            .iter()
            .map(|&c| to_byte(c))
            .collect()
    }

    #[test]
    fn the_centreline_of_a_rendered_catheter_is_its_projected_axis() {
        for (force, angles, size) in [
            (Vec3::new(0.1, -0.05, -0.15), [0.0, 0.0], 128),
            (Vec3::new(-0.2, 0.1, -0.1), [90.0, 0.0], 128),
            (Vec3::new(0.0, 0.0, 0.0), [-30.0, 20.0], 160),
        ] {
            let view = CArm::cardiac(angles[0], angles[1], ImageSize::square(size));
            let shape = bent_catheter(force);
            let mask = mask_of(&shape, &view);
            let line = extract_centreline(
                &Mask::coverage8(size, size, &mask),
                "A",
                &CentrelineSettings::default(),
            )
            .unwrap();
            let truth = projected(&shape, &view);
            let errors: Vec<f64> = line
                .points_px
                .iter()
                .map(|&p| distance_to(&truth, p))
                .collect();
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            let max = errors.iter().fold(0.0f64, |m, &e| m.max(e));
            assert!(mean < 0.03 && max < 0.2, "mean {mean} px, max {max} px");
            // Ordered from the border to the tip, which is found along the curve too.
            assert!(line.proximal_at_border && !line.tip_at_border);
            let first = line.points_px[0];
            let border = first[0]
                .min(first[1])
                .min(size as f64 - first[0])
                .min(size as f64 - first[1]);
            assert!(border < 1.0, "{first:?}");
            let tip = view.project(shape.tip_mm());
            let tip_error = (line.tip_px()[0] - tip.u).hypot(line.tip_px()[1] - tip.v);
            eprintln!("tip {tip_error}");
            assert!(tip_error < 0.3, "tip off by {tip_error} px");
            // Equal steps of at most the spacing; the shaft's width is the projected diameter.
            let steps: Vec<f64> = line.arc_px.windows(2).map(|w| w[1] - w[0]).collect();
            assert!(
                steps.iter().all(|&s| s <= 1.0 + 1e-9 && s > 0.9),
                "{steps:?}"
            );
            let expected_width = 2.33 / view.isocentre_mm_per_px();
            assert!(
                (line.width_px - expected_width).abs() < 0.1 * expected_width,
                "{} vs {expected_width}",
                line.width_px
            );
        }
    }

    #[test]
    fn soft_masks_give_the_same_centreline() {
        let view = CArm::cardiac(0.0, 0.0, ImageSize::square(96));
        let shape = bent_catheter(Vec3::new(0.15, 0.0, -0.1));
        let tube = rasterize_catheter(&shape, 2.33, &CatheterDesign::default(), &view);
        let soft = extract_centreline(
            &Mask::soft(96, 96, &tube.coverage),
            "B",
            &CentrelineSettings {
                spacing_px: 2.0,
                ..CentrelineSettings::default()
            },
        )
        .unwrap();
        let truth = projected(&shape, &view);
        for &p in &soft.points_px {
            assert!(distance_to(&truth, p) < 0.25);
        }
        let steps: Vec<f64> = soft.arc_px.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(steps.iter().all(|&s| s <= 2.0 + 1e-9 && s > 1.8));
    }

    #[test]
    fn a_catheter_inside_the_image_starts_at_the_end_nearer_the_border() {
        // A horizontal bar from u = 20 to u = 50 at v = 30 in a 64 x 64 mask.
        let (w, h) = (64, 64);
        let mut mask = vec![0u8; w * h];
        fill(&mut mask, w, 20..51, 28..33, 255);
        let line = centreline8(w, h, &mask, "A").unwrap();
        assert!(!line.proximal_at_border && !line.tip_at_border);
        // u = 20 is 20 px from the border, u = 51 is 13 px from it.
        assert!(line.points_px[0][0] > 45.0, "{:?}", line.points_px[0]);
        assert!((line.points_px[0][1] - 30.5).abs() < 0.05);
        // A hint turns it round.
        let hinted = extract_centreline(
            &Mask::coverage8(w, h, &mask),
            "A",
            &CentrelineSettings {
                proximal_hint_px: Some([0.0, 30.0]),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(hinted.points_px[0][0] < 25.0);
    }

    #[test]
    fn a_blob_beside_the_catheter_is_set_aside_and_one_beyond_its_tip_is_not() {
        // A catheter coming up from the bottom edge (u 30-34, tip at v = 20) and, 2 px to its
        // right, a bar of 45 px beside its shaft: a background's edge read as catheter.
        let n = 64;
        let mut mask = vec![0u8; n * n];
        fill(&mut mask, n, 30..34, 20..n, 255);
        let mut beside = mask.clone();
        fill(&mut beside, n, 36..39, 35..50, 255);
        let line = centreline8(n, n, &beside, "A").unwrap();
        assert_eq!(line.set_aside_px, vec![45]);
        // The bar is not read: the centreline keeps to the catheter's axis, u = 32.
        for p in &line.points_px {
            assert!((p[0] - 32.0).abs() < 0.05, "{p:?}");
        }
        // The tip's centre lies a cap's depth inside the bar's square end, v = 20.
        assert!(
            (20.0..22.0).contains(&line.tip_px()[1]),
            "{:?}",
            line.tip_px()
        );
        assert!(
            centreline8(n, n, &mask, "A")
                .unwrap()
                .set_aside_px
                .is_empty()
        );

        // A piece 5 px past the tip may be the catheter's own continuation: ambiguous.
        let mut beyond = mask.clone();
        fill(&mut beyond, n, 30..34, 8..15, 255);
        let err = centreline8(n, n, &beyond, "A").unwrap_err();
        assert_eq!(
            err,
            CentrelineError::SeveralBlobs {
                view: "A".into(),
                sizes: vec![176, 28]
            }
        );
        // So is a second blob half the catheter's size or more, even beside it.
        let mut second = mask.clone();
        fill(&mut second, n, 50..54, 20..n, 255);
        assert!(matches!(
            centreline8(n, n, &second, "A").unwrap_err(),
            CentrelineError::SeveralBlobs { .. }
        ));
    }

    #[test]
    fn bad_masks_are_named_errors() {
        let (w, h) = (40, 30);
        let empty = vec![0u8; w * h];
        let err = centreline8(w, h, &empty, "A").unwrap_err();
        assert!(matches!(err, CentrelineError::Empty { .. }), "{err}");
        assert!(err.to_string().starts_with("view A: the mask is empty"));

        // Two bars of 5 x 20 and 4 x 15 pixels.
        let mut two = vec![0u8; w * h];
        fill(&mut two, w, 5..10, 0..20, 255);
        fill(&mut two, w, 25..29, 5..20, 255);
        let err = centreline8(w, h, &two, "B").unwrap_err();
        assert_eq!(
            err,
            CentrelineError::SeveralBlobs {
                view: "B".into(),
                sizes: vec![100, 60]
            }
        );
        assert_eq!(
            err.to_string(),
            "view B: the mask has 2 separate blobs of 100, 60 pixels, expected one catheter"
        );
        // A speck beside the catheter is ignored.
        let mut speck = two.clone();
        fill(&mut speck, w, 25..29, 5..20, 0);
        speck[25 * w + 30] = 255;
        assert!(centreline8(w, h, &speck, "B").is_ok());

        // A hairpin: two legs side by side, one of them reaching the border.
        let mut hairpin = vec![0u8; w * h];
        fill(&mut hairpin, w, 10..15, 5..h, 255);
        fill(&mut hairpin, w, 15..20, 5..20, 255);
        let err = centreline8(w, h, &hairpin, "A").unwrap_err();
        assert!(matches!(err, CentrelineError::NotATube { .. }), "{err}");
        assert!(err.to_string().contains("times as wide"), "{err}");
        // A branch off the catheter's side.
        let n = 60;
        let mut branch = vec![0u8; n * n];
        fill(&mut branch, n, 28..33, 0..50, 255);
        fill(&mut branch, n, 33..50, 20..25, 255);
        let err = centreline8(n, n, &branch, "A").unwrap_err();
        assert!(
            err.to_string().contains("lie off the centreline's tube"),
            "{err}"
        );

        let mut dot = vec![0.0f32; w * h];
        fill(&mut dot, w, 10..14, 10..14, 0.9);
        let err =
            extract_centreline(&Mask::soft(w, h, &dot), "A", &Default::default()).unwrap_err();
        assert!(matches!(err, CentrelineError::TooShort { .. }), "{err}");
        let err =
            extract_centreline(&Mask::soft(w, h + 1, &dot), "A", &Default::default()).unwrap_err();
        assert!(matches!(err, CentrelineError::WrongSize { .. }), "{err}");
    }

    /// A `size` x `size` coverage mask of a tube `width_px` wide around the polyline `line`
    /// (pixels), each pixel's coverage from 4 x 4 samples.
    fn tube_mask(size: usize, line: &[[f64; 2]], width_px: f64) -> Vec<f32> {
        let mut mask = vec![0.0f32; size * size];
        for (i, value) in mask.iter_mut().enumerate() {
            let (x, y) = ((i % size) as f64, (i / size) as f64);
            let inside = (0..16)
                .filter(|k| {
                    let p = [
                        x + (k % 4) as f64 / 4.0 + 0.125,
                        y + (k / 4) as f64 / 4.0 + 0.125,
                    ];
                    distance_to(line, p) <= width_px / 2.0
                })
                .count();
            *value = inside as f32 / 16.0;
        }
        mask
    }

    #[test]
    fn a_catheter_crossing_itself_is_seen_and_a_painted_patch_is_not() {
        let size = 224;
        // Up from the bottom border, then a loop that crosses the shaft (a trochoid).
        let mut line = vec![[100.0, 224.5]];
        line.extend((0..=400).map(|k| {
            let t = k as f64 * 0.02;
            [
                100.0 + 28.0 * t.sin(),
                200.0 - 10.0 * t - 28.0 * (1.0 - t.cos()),
            ]
        }));
        let looped = tube_mask(size, &line, 5.0);
        let settings = CentrelineSettings::default();
        let mask = Mask::soft(size, size, &looped);
        let err = extract_centreline(&mask, "A", &settings).unwrap_err();
        assert!(
            matches!(
                err,
                CentrelineError::NotATube {
                    misfit: TubeMisfit::OffTube { .. },
                    ..
                }
            ),
            "{err}"
        );
        assert!(matches!(
            catheter_seen(&mask, "A", &settings),
            Ok(CatheterSeen::Tangled(TubeMisfit::OffTube { .. }))
        ));
        // The same blob beside specks (as a network paints uniform noise: each speck too small
        // to count as a blob, together twice the blob's pixels) is no catheter; a clean tube
        // beside them still is.
        let specks = |mut mask: Vec<f32>| {
            for k in 0..300 {
                let (x, y) = (150 + 4 * (k % 17), 4 + 4 * (k / 17));
                for (dx, dy) in [
                    (0, 0),
                    (1, 0),
                    (0, 1),
                    (1, 1),
                    (2, 0),
                    (2, 1),
                    (0, 2),
                    (1, 2),
                    (2, 2),
                ] {
                    mask[(y + dy) * size + x + dx] = 1.0;
                }
            }
            mask
        };
        let painted = specks(looped);
        let why = catheter_seen(&Mask::soft(size, size, &painted), "A", &settings).unwrap_err();
        assert!(
            matches!(why, NoCatheter::Scattered { in_blob, .. } if in_blob < 0.5),
            "{why}"
        );
        assert!(
            why.to_string().starts_with(
                "view A: no catheter found (the pixels read as catheter are scattered"
            ),
            "{why}"
        );
        let straight = specks(tube_mask(size, &[[100.0, 224.5], [100.0, 60.0]], 5.0));
        assert_eq!(
            catheter_seen(&Mask::soft(size, size, &straight), "A", &settings),
            Ok(CatheterSeen::Tube)
        );
    }
}
