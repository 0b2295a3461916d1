//! The steps of [`super::extract_centreline`]: the catheter's largest blob and where it meets
//! the border, the geodesic through it, its refinement onto the ridge of the mask, the tip, and
//! the polyline helpers they share.

use super::*;

/// The catheter's blob, and the blobs set aside beside it.
pub(super) struct CatheterBlob {
    /// The catheter's pixels, sorted.
    pub pixels: Vec<usize>,
    /// The pixels of each significant blob set aside beside the catheter, largest first.
    pub set_aside: Vec<Vec<usize>>,
}

/// The pixels of the catheter's blob: the largest one, with any other significant blob set
/// aside when it lies beside the catheter rather than beyond its tip
/// ([`CentrelineSettings::set_aside_fraction`], [`CentrelineSettings::beyond_tip_px`]); the
/// error when there is no blob or the blobs leave it ambiguous.
pub(super) fn catheter_blob(
    inside: &[bool],
    width: usize,
    height: usize,
    view: &str,
    settings: &CentrelineSettings,
) -> Result<CatheterBlob, CentrelineError> {
    let mut label = vec![usize::MAX; inside.len()];
    let mut blobs: Vec<Vec<usize>> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..inside.len() {
        if !inside[start] || label[start] != usize::MAX {
            continue;
        }
        let id = blobs.len();
        let mut pixels = Vec::new();
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            pixels.push(i);
            for (j, _) in neighbours(i, width, height) {
                if inside[j] && label[j] == usize::MAX {
                    label[j] = id;
                    stack.push(j);
                }
            }
        }
        blobs.push(pixels);
    }
    if blobs.is_empty() {
        return Err(CentrelineError::Empty { view: view.into() });
    }
    blobs.sort_by_key(|b| Reverse(b.len()));
    let largest = blobs[0].len();
    let significant =
        (settings.min_blob_px as f64).max(settings.min_blob_fraction * largest as f64);
    blobs.retain(|b| b.len() as f64 >= significant);
    if blobs.is_empty() {
        // Only specks: nothing that could be a catheter.
        return Err(CentrelineError::Empty { view: view.into() });
    }
    let mut catheter = blobs.remove(0);
    catheter.sort_unstable();
    if !blobs.is_empty() && !all_beside(&catheter, &blobs, width, height, settings) {
        let mut sizes = vec![catheter.len()];
        sizes.extend(blobs.iter().map(Vec::len));
        return Err(CentrelineError::SeveralBlobs {
            view: view.into(),
            sizes,
        });
    }
    Ok(CatheterBlob {
        pixels: catheter,
        set_aside: blobs,
    })
}

/// Whether every one of `others` lies beside the `catheter` blob, so that it can be set aside:
/// the catheter enters the view from its border, each other blob is smaller than
/// [`CentrelineSettings::set_aside_fraction`] of it, and none lies beyond its tip (a blob whose
/// nearest pixel to the tip is within [`CentrelineSettings::beyond_tip_px`] of its nearest to
/// the catheter may be the catheter's own continuation, broken where the mask dips below half
/// coverage). A blob beside the shaft is another device or a structure of the background read
/// as catheter; a catheter cut in two is an error, not a guess.
fn all_beside(
    catheter: &[usize],
    others: &[Vec<usize>],
    width: usize,
    height: usize,
    settings: &CentrelineSettings,
) -> bool {
    let on_border = |i: usize| {
        let (x, y) = (i % width, i / width);
        x == 0 || y == 0 || x == width - 1 || y == height - 1
    };
    let border: Vec<usize> = catheter.iter().copied().filter(|&i| on_border(i)).collect();
    if border.is_empty() {
        return false;
    }
    let mut in_blob = vec![false; width * height];
    for &i in catheter {
        in_blob[i] = true;
    }
    let (tip, _, _) = geodesic(&in_blob, width, height, &border);
    let at = |i: usize| [(i % width) as f64, (i / width) as f64];
    let distance = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let tip = at(tip);
    others.iter().all(|blob| {
        if blob.len() as f64 > settings.set_aside_fraction * catheter.len() as f64 {
            return false;
        }
        let to_tip = blob
            .iter()
            .map(|&i| distance(at(i), tip))
            .fold(f64::INFINITY, f64::min);
        let to_catheter = blob
            .iter()
            .flat_map(|&i| catheter.iter().map(move |&j| distance(at(i), at(j))))
            .fold(f64::INFINITY, f64::min);
        to_tip > to_catheter + settings.beyond_tip_px
    })
}

/// Groups border pixels into runs of 8-connected neighbours.
pub(super) fn border_runs(border: &[usize], width: usize) -> Vec<Vec<usize>> {
    let mut runs: Vec<Vec<usize>> = Vec::new();
    let mut assigned = vec![false; border.len()];
    for start in 0..border.len() {
        if assigned[start] {
            continue;
        }
        assigned[start] = true;
        let mut run = vec![border[start]];
        let mut k = 0;
        while k < run.len() {
            let (x, y) = ((run[k] % width) as isize, (run[k] / width) as isize);
            for (j, &other) in border.iter().enumerate() {
                if assigned[j] {
                    continue;
                }
                let (ox, oy) = ((other % width) as isize, (other / width) as isize);
                if (ox - x).abs() <= 1 && (oy - y).abs() <= 1 {
                    assigned[j] = true;
                    run.push(other);
                }
            }
            k += 1;
        }
        runs.push(run);
    }
    runs
}

/// Shortest paths inside `in_blob` from `sources` (8-neighbours, steps of 1 and √2 weighted 5
/// and 7): the farthest pixel, its distance and every pixel's predecessor.
pub(super) fn geodesic(
    in_blob: &[bool],
    width: usize,
    height: usize,
    sources: &[usize],
) -> (usize, u32, Vec<Option<usize>>) {
    let mut distance = vec![u32::MAX; in_blob.len()];
    let mut previous = vec![None; in_blob.len()];
    let mut heap = BinaryHeap::new();
    for &s in sources {
        distance[s] = 0;
        heap.push(Reverse((0u32, s)));
    }
    let (mut far, mut far_distance) = (sources[0], 0);
    while let Some(Reverse((d, i))) = heap.pop() {
        if d > distance[i] {
            continue;
        }
        if d > far_distance {
            (far, far_distance) = (i, d);
        }
        for (j, diagonal) in neighbours(i, width, height) {
            if !in_blob[j] {
                continue;
            }
            let nd = d + if diagonal { 7 } else { 5 };
            if nd < distance[j] {
                distance[j] = nd;
                previous[j] = Some(i);
                heap.push(Reverse((nd, j)));
            }
        }
    }
    (far, far_distance, previous)
}

/// Moves every point to the centroid of the mask along its normal within `reach` pixels; returns
/// the moved points and the profile widths (the integral of each profile; NaN where the profile
/// is empty).
pub(super) fn refine(
    field: &Field<'_>,
    points: &[[f64; 2]],
    reach: f64,
) -> (Vec<[f64; 2]>, Vec<f64>) {
    const STEP: f64 = 0.25;
    let n = points.len();
    let steps = (reach / STEP).ceil() as isize;
    let mut refined = Vec::with_capacity(n);
    let mut widths = Vec::with_capacity(n);
    for k in 0..n {
        let t = tangent(points, k);
        let normal = [-t[1], t[0]];
        let p = points[k];
        let (mut total, mut moment) = (0.0, 0.0);
        for along in [-0.5, 0.0, 0.5] {
            for j in -steps..=steps {
                let off = j as f64 * STEP;
                let c = field.sample(
                    p[0] + normal[0] * off + t[0] * along,
                    p[1] + normal[1] * off + t[1] * along,
                );
                total += c;
                moment += c * off;
            }
        }
        let width = total * STEP / 3.0;
        if width > 0.2 {
            let shift = (moment / total).clamp(-reach, reach);
            refined.push([p[0] + normal[0] * shift, p[1] + normal[1] * shift]);
            widths.push(width);
        } else {
            refined.push(p);
            widths.push(f64::NAN);
        }
    }
    (refined, widths)
}

/// Cuts or extends the distal end so that it ends at the tip's centre. The mask ends with the
/// tube's round cap, a half disc of `radius` beyond that centre: the centre is where the mask's
/// area still ahead, within a band along the end's direction, is that half disc's. An area
/// averages the outline's pixels, so a ragged outline moves it far less than it moves the point
/// where the coverage along the axis falls below one half.
pub(super) fn place_tip(
    field: &Field<'_>,
    mut points: Vec<[f64; 2]>,
    radius: f64,
) -> Vec<[f64; 2]> {
    let n = points.len();
    let end = points[n - 1];
    let back = points[n.saturating_sub(4)];
    let d = [end[0] - back[0], end[1] - back[1]];
    let norm = d[0].hypot(d[1]);
    if norm < 1e-9 || radius <= 0.0 {
        return points;
    }
    let t = [d[0] / norm, d[1] / norm];
    let normal = [-t[1], t[0]];
    const STEP: f64 = 0.25;
    let band = ((radius + 1.5) / STEP).ceil() as isize;
    let (first, last) = (
        (-(2.0 * radius + 2.0) / STEP).floor() as isize,
        ((2.0 * radius + 4.0) / STEP).ceil() as isize,
    );
    // The mask's width at each step along the end's direction.
    let widths: Vec<f64> = (first..=last)
        .map(|k| {
            let s = k as f64 * STEP;
            (-band..=band)
                .map(|j| {
                    let o = j as f64 * STEP;
                    field.sample(
                        end[0] + t[0] * s + normal[0] * o,
                        end[1] + t[1] * s + normal[1] * o,
                    )
                })
                .sum::<f64>()
                * STEP
        })
        .collect();
    // The mask must end inside the band, after a stretch of full shaft.
    if widths[widths.len() - 1] > 0.25 * radius || widths[0] < radius {
        return points;
    }
    let cap = core::f64::consts::PI * radius * radius / 2.0;
    let mut ahead = 0.0;
    let mut tip = None;
    for k in (0..widths.len() - 1).rev() {
        let slice = 0.5 * (widths[k] + widths[k + 1]) * STEP;
        if ahead + slice >= cap {
            let f = (cap - ahead) / slice;
            tip = Some((first + k as isize + 1) as f64 * STEP - f * STEP);
            break;
        }
        ahead += slice;
    }
    let Some(tip_offset) = tip else {
        return points;
    };
    if tip_offset >= 0.0 {
        points.push([end[0] + t[0] * tip_offset, end[1] + t[1] * tip_offset]);
        points
    } else {
        let length = polyline_length(&points);
        truncate(&points, (length + tip_offset).max(0.0))
    }
}

/// Unit tangent at point `k` (central difference over two points each side).
pub(super) fn tangent(points: &[[f64; 2]], k: usize) -> [f64; 2] {
    let n = points.len();
    let (a, b) = (points[k.saturating_sub(2)], points[(k + 2).min(n - 1)]);
    let d = [b[0] - a[0], b[1] - a[1]];
    let norm = d[0].hypot(d[1]);
    if norm > 0.0 {
        [d[0] / norm, d[1] / norm]
    } else {
        [1.0, 0.0]
    }
}

/// Moving average over `half` points each side, the window shrinking at the ends so that the end
/// points stay.
pub(super) fn smooth(points: &[[f64; 2]], half: usize) -> Vec<[f64; 2]> {
    let n = points.len();
    (0..n)
        .map(|k| {
            let h = half.min(k).min(n - 1 - k);
            let window = &points[k - h..=k + h];
            let m = window.len() as f64;
            [
                window.iter().map(|p| p[0]).sum::<f64>() / m,
                window.iter().map(|p| p[1]).sum::<f64>() / m,
            ]
        })
        .collect()
}

/// Cumulative arc length along a polyline.
pub(crate) fn arc_lengths(points: &[[f64; 2]]) -> Vec<f64> {
    let mut arc = Vec::with_capacity(points.len());
    let mut s = 0.0;
    for (k, p) in points.iter().enumerate() {
        if k > 0 {
            let q = points[k - 1];
            s += (p[0] - q[0]).hypot(p[1] - q[1]);
        }
        arc.push(s);
    }
    arc
}

pub(super) fn polyline_length(points: &[[f64; 2]]) -> f64 {
    arc_lengths(points).last().copied().unwrap_or(0.0)
}

/// The point at arc length `s` along a polyline with cumulative lengths `arc`.
pub(crate) fn point_at(points: &[[f64; 2]], arc: &[f64], s: f64) -> [f64; 2] {
    let n = points.len();
    if n == 1 || s <= 0.0 {
        return points[0];
    }
    let k = arc.partition_point(|&a| a < s).clamp(1, n - 1);
    let span = arc[k] - arc[k - 1];
    let f = if span > 0.0 {
        ((s - arc[k - 1]) / span).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let (a, b) = (points[k - 1], points[k]);
    [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f]
}

/// The polyline resampled at equal arc-length steps of at most `spacing`, keeping both ends.
pub(super) fn resample(points: &[[f64; 2]], spacing: f64) -> Vec<[f64; 2]> {
    let arc = arc_lengths(points);
    let length = arc.last().copied().unwrap_or(0.0);
    if points.len() < 2 || length <= 0.0 {
        return points.to_vec();
    }
    let segments = (length / spacing).ceil().max(1.0) as usize;
    (0..=segments)
        .map(|k| point_at(points, &arc, length * k as f64 / segments as f64))
        .collect()
}

/// The first `length` of the polyline.
pub(super) fn truncate(points: &[[f64; 2]], length: f64) -> Vec<[f64; 2]> {
    let arc = arc_lengths(points);
    let mut out: Vec<[f64; 2]> = points
        .iter()
        .zip(&arc)
        .take_while(|(_, a)| **a < length)
        .map(|(p, _)| *p)
        .collect();
    out.push(point_at(points, &arc, length));
    out
}

/// The median of the values that are not NaN (0 when there are none).
pub(super) fn median(values: &[f64]) -> f64 {
    quantile(values, 0.5)
}

/// The `q` quantile (lower) of the values that are not NaN (0 when there are none).
pub(super) fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q) as usize]
}
