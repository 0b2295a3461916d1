"""Where a network's masks fail on a simulated dataset (docs/results.md, "What limits the masks
off the bench").

Reads what `hnet eval` wrote for the dataset's pairs (`--predictions`: each pair's catheter IoU
per view; `--masks`: its predicted masks and error maps, white found, blue missed, red spurious)
and the pairs' twin records, and prints:

  - per-pair IoU by quartile of each scene setting (catheter length, stiffness, pre-curve, base
    tilt, force magnitude) and of the label mask's area;
  - for long catheters (>= --long-mm) and the others, IoU by distance from the tip along the
    catheter and by the catheter's direction in the view (each error-map pixel takes its nearest
    centreline point), and by stretch (the electrodes, the shaft up to 30 mm from the tip, the
    shaft beyond) and direction (within 30 degrees of horizontal or steeper), and the shaft's IoU
    by direction and by its distance from the nearest background patch seam parallel to it
    (XRay backgrounds' grid of patches) or by its local contrast (how much darker than the
    median of its neighbourhood the view is there);
  - with --bench DIR, IoU by how often that dataset's label masks cover each region of the view
    (the position prior a network trained there may have learned).

Usage:
  hnet eval --weights W --data D --split train --no-physics --predictions p.csv --masks m/
  python bench/mask_errors.py --data D --predictions p.csv --masks m/ [--bench B]
Needs numpy and Pillow.
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from PIL import Image, ImageFilter

# Error-map colours, as `hnet eval --masks` writes them (crates/hnet-cli/src/evaluation.rs).
FOUND = (255, 255, 255)
MISSED = (64, 128, 255)
SPURIOUS = (255, 64, 64)
# Label masks are 8-bit coverage; a pixel is catheter at or above half (MASK_THRESHOLD).
HALF = 128
GRID = 8


def record(data, pair_id):
    return json.loads((data / "samples" / f"{pair_id}.json").read_text())["record"]


def error_classes(path):
    e = np.asarray(Image.open(path).convert("RGB")).astype(int)
    return [(e == colour).all(-1) for colour in (FOUND, MISSED, SPURIOUS)]


def quartile_table(name, values, iou):
    """Mean IoU (one column per view) of the pairs in each quartile of `values`."""

    def mean(k):
        return "/".join(f"{iou[k, v].mean():.3f}" for v in range(iou.shape[1]))

    q = np.quantile(values, [0, 0.25, 0.5, 0.75, 1])
    if q[0] == q[-1]:
        print(f"{name:12s} constant {q[0]:.4g}: IoU {mean(slice(None))}")
        return
    bins = np.digitize(values, q[1:-1])
    cells = [f"{q[i]:.4g}-{q[i + 1]:.4g}: {mean(bins == i)}" for i in range(4) if (bins == i).any()]
    print(f"{name:12s} " + " | ".join(cells))


def by_setting(data, rows, iou):
    settings = {"length mm": [], "stiffness": [], "pre-curve": [], "tilt deg": [], "|F| N": []}
    for r in rows:
        scene = record(data, r["id"])["scene"]
        settings["length mm"].append(scene["length_mm"])
        settings["stiffness"].append(scene["bending_stiffness_n_m2"])
        settings["pre-curve"].append(scene["precurvature_per_mm"])
        settings["tilt deg"].append(scene["base_tilt_deg"])
        settings["|F| N"].append(float(np.linalg.norm(scene["tip_force_n"])))
    print("per-pair catheter IoU A/B by quartile")
    for name, values in settings.items():
        quartile_table(name, np.array(values), iou)
    for v, view in enumerate("ab"):
        area = np.array(
            [
                (np.asarray(Image.open(data / "samples" / f"{r['id']}_mask_{view}.png").convert("L")) >= HALF).sum()
                for r in rows
            ]
        )
        quartile_table(f"mask px {view.upper()}", area, iou[:, v : v + 1])


def iou_table(title, edges, counts, unit):
    """IoU per bin of `edges` from the found / missed / spurious pixel counts of each group."""
    for group in ("other", "long"):
        if (group, "found") not in counts:
            continue
        print(f"{title(group)}")
        f, m, s = (counts.get((group, n), np.zeros(len(edges) - 1)) for n in ("found", "missed", "spurious"))
        for i in range(len(edges) - 1):
            union = max(f[i] + m[i] + s[i], 1)
            print(
                f"  {edges[i]:2.0f}-{edges[i + 1]:2.0f} {unit}: IoU {f[i] / union:.3f} "
                f"(found {int(f[i])}, missed {int(m[i])}, spurious {int(s[i])})"
            )


def electrodes_end_mm(data):
    """Distance from the tip to the proximal edge of the catheter's last electrode, mm (the
    dataset's twin settings; the shaft beyond it is faint in X-ray)."""
    design = json.loads((data / "dataset.json").read_text())["source"]["twin"]["catheter"]
    rings = [r["from_tip_mm"] + r["width_mm"] for r in design["rings"]]
    return max([design["tip_electrode_mm"], *rings])


def patch_grid(data):
    """Patches per side of the dataset's X-ray backgrounds, or None (no patch grid)."""
    patches = json.loads((data / "dataset.json").read_text())["source"]["twin"].get("patches")
    return patches["grid"] if patches else None


def local_contrast(path, side):
    """How much darker each pixel of a view is than the median of its neighbourhood (about a
    twentieth of the view), relative to that median: 0 on the background, positive on the
    catheter."""
    grey = Image.open(path).convert("L").resize((side, side), Image.BILINEAR)
    window = max(3, side // 20) | 1
    background = np.asarray(grey.filter(ImageFilter.MedianFilter(window))).astype(float)
    return (background - np.asarray(grey).astype(float)) / np.maximum(background, 1.0)


# The shaft's pools: distance from the nearest parallel patch seam (pixels) and local contrast.
SEAM_EDGES = [0, 2, 4, 8, 14, np.inf]
CONTRAST_EDGES = [-np.inf, 0.02, 0.04, 0.06, 0.09, 0.13, np.inf]


def shaft_table(title, edges, pool, unit):
    print(title)
    for steep, direction in ((0, "< 30 deg"), (1, ">= 30 deg")):
        cells = []
        for b in range(len(edges) - 1):
            f, m, sp = pool[steep, b]
            lo, hi = edges[b], edges[b + 1]
            span = f"< {hi:g}" if np.isinf(lo) else f">= {lo:g}" if np.isinf(hi) else f"{lo:g}-{hi:g}"
            cells.append(f"{span}{unit} {f / max(f + m + sp, 1):.3f} ({int(f + m)} px)")
        print(f"  {direction:9s} " + " | ".join(cells))


def along_catheter(data, masks, rows, long_mm):
    edges = [0, 5, 10, 20, 30, 40, 50, 61]
    # The centreline's direction in the view, degrees from the image's horizontal (0-90).
    angle_edges = [0, 15, 30, 45, 60, 75, 90.01]
    counts = {}
    by_angle = {}
    shaft_from = electrodes_end_mm(data)
    stretch_edges = [0, shaft_from, 30, np.inf]
    # (stretch, steep) -> [found, missed, spurious] pixels, every catheter length.
    by_stretch = np.zeros((3, 2, 3))
    # Missed pixels of each long catheter's view: (missed, id, view, IoU).
    long_views = []
    grid = patch_grid(data)
    # (steep, bin, found/missed/spurious) shaft pixels.
    by_seam = np.zeros((2, len(SEAM_EDGES) - 1, 3))
    by_contrast = np.zeros((2, len(CONTRAST_EDGES) - 1, 3))
    for r in rows:
        rec = record(data, r["id"])
        length = rec["scene"]["length_mm"]
        group = "long" if length >= long_mm else "other"
        centreline = np.array(rec["centreline_mm"])
        # Each centreline point's distance from the tip along the catheter, mm.
        to_tip = np.array(rec["arc_mm"])[-1] - np.array(rec["arc_mm"])
        for v, view in enumerate("ab"):
            classes = error_classes(masks / f"{r['id']}_errors_{view}.png")
            side = classes[0].shape[1]
            camera = np.array(rec["views"][v]["camera_matrix"])
            size = rec["views"][v]["carm"]["image_size"]["width"]
            h = np.c_[centreline, np.ones(len(centreline))] @ camera.T
            uv = h[:, :2] / h[:, 2:] * side / size
            tangent = np.gradient(uv, axis=0)
            angle = np.degrees(np.arctan2(np.abs(tangent[:, 1]), np.abs(tangent[:, 0])))
            ys, xs = np.nonzero(np.ones_like(classes[0]))
            pixels = np.stack([xs + 0.5, ys + 0.5], 1)
            contrast = local_contrast(data / "samples" / f"{r['id']}_view_{view}.png", side)
            if group == "long":
                long_views.append((int(classes[1].sum()), r["id"], view, float(r[f"catheter_iou_{view}"])))
            for name, m in zip(("found", "missed", "spurious"), classes):
                p = pixels[m.ravel()]
                if len(p) == 0:
                    continue
                nearest = ((p[:, None, :] - uv[None, :, :]) ** 2).sum(-1).argmin(1)
                hist = np.histogram(to_tip[nearest], edges)[0]
                counts[(group, name)] = counts.get((group, name), 0) + hist
                hist = np.histogram(angle[nearest], angle_edges)[0]
                by_angle[(group, name)] = by_angle.get((group, name), 0) + hist
                stretch = np.digitize(to_tip[nearest], stretch_edges[1:-1])
                steep = (angle[nearest] >= 30).astype(int)
                k = ("found", "missed", "spurious").index(name)
                np.add.at(by_stretch, (stretch, steep, k), 1)
                shaft = to_tip[nearest] > shaft_from
                xy = p[shaft].astype(int)
                bins = np.digitize(contrast[xy[:, 1], xy[:, 0]], CONTRAST_EDGES[1:-1])
                np.add.at(by_contrast, (steep[shaft], bins, k), 1)
                if grid:
                    # Distance from the nearest interior seam across the shaft's direction:
                    # horizontal seams for sideways stretches, vertical ones for steeper.
                    cell = side / grid
                    off = np.where(steep[shaft, None] == 1, p[shaft][:, :1], p[shaft][:, 1:]).ravel()
                    seam = np.abs((off + cell / 2) % cell - cell / 2)
                    np.add.at(by_seam, (steep[shaft], np.digitize(seam, SEAM_EDGES[1:-1]), k), 1)

    def label(group):
        return f">= {long_mm} mm" if group == "long" else f"< {long_mm} mm"

    iou_table(lambda g: f"catheters {label(g)}: IoU by distance from the tip", edges, counts, "mm")
    iou_table(
        lambda g: f"catheters {label(g)}: IoU by the catheter's direction in the view, degrees from horizontal",
        angle_edges,
        by_angle,
        "deg",
    )
    print("all catheters: IoU by stretch and direction in the view")
    names = (f"electrodes, 0-{shaft_from:g} mm", f"shaft, {shaft_from:g}-30 mm", "shaft, 30 mm on")
    for k, stretch in enumerate(names):
        cells = []
        for steep, direction in ((0, "< 30 deg"), (1, ">= 30 deg")):
            f, m, sp = by_stretch[k, steep]
            cells.append(f"{direction} IoU {f / max(f + m + sp, 1):.3f} ({int(f + m)} px)")
        print(f"  {stretch:22s} " + " | ".join(cells))
    if grid:
        shaft_table(
            f"shaft (from {shaft_from:g} mm): IoU by distance from the nearest parallel patch seam ({grid}x{grid} patches)",
            SEAM_EDGES,
            by_seam,
            " px",
        )
    shaft_table(
        f"shaft (from {shaft_from:g} mm): IoU by local contrast (darker than the neighbourhood's median, relative)",
        CONTRAST_EDGES,
        by_contrast,
        "",
    )
    if long_views:
        long_views.sort(reverse=True)
        share = sum(v[0] for v in long_views[:10]) / max(sum(v[0] for v in long_views), 1)
        print(f"the 10 of {len(long_views)} long catheters' views that miss most hold {share:.0%} of their missed pixels:")
        for missed, pair_id, view, iou in long_views[:10]:
            print(f"  {pair_id} view {view.upper()}: {missed} missed, IoU {iou:.3f}")


def by_region(bench, masks, rows):
    first = error_classes(masks / f"{rows[0]['id']}_errors_a.png")[0]
    side = first.shape[0]
    totals = np.zeros((3, 2, side, side))
    for r in rows:
        for v, view in enumerate("ab"):
            for k, m in enumerate(error_classes(masks / f"{r['id']}_errors_{view}.png")):
                totals[k, v] += m
    cover = np.zeros((2, side, side))
    for v, view in enumerate("ab"):
        files = sorted((bench / "samples").glob(f"*_mask_{view}.png"))[:300]
        for path in files:
            cover[v] += np.asarray(Image.open(path).convert("L").resize((side, side), Image.BILINEAR)) >= HALF
        cover[v] /= len(files)

    def cells(a):
        return a.reshape(a.shape[0], GRID, side // GRID, GRID, side // GRID).sum((2, 4))

    found, missed, spurious = (cells(t) for t in totals)
    covered = cells(cover) / (side // GRID) ** 2
    catheter = found + missed
    print(f"IoU by how often {bench.name}'s label masks cover the region ({GRID}x{GRID} grid)")
    buckets = (
        ("never covered", covered == 0),
        ("covered < 1 %", (covered > 0) & (covered < 0.01)),
        ("covered >= 1 %", covered >= 0.01),
    )
    for name, k in buckets:
        union = max((found + missed + spurious)[k].sum(), 1)
        print(f"  {name:15s}: {catheter[k].sum() / catheter.sum():.2f} of the catheter pixels, IoU {found[k].sum() / union:.3f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="the simulated dataset evaluated")
    parser.add_argument("--predictions", type=Path, required=True, help="hnet eval --predictions file")
    parser.add_argument("--masks", type=Path, required=True, help="hnet eval --masks folder")
    parser.add_argument("--bench", type=Path, help="a dataset whose label masks give the position prior")
    parser.add_argument("--long-mm", type=float, default=55.0, help="catheters this long or longer are 'long'")
    args = parser.parse_args()
    rows = [r for r in csv.DictReader(args.predictions.open()) if r.get("catheter_iou_a")]
    if not rows:
        raise SystemExit(f"{args.predictions}: no catheter IoU columns (a network without masks?)")
    iou = np.array([[float(r["catheter_iou_a"]), float(r["catheter_iou_b"])] for r in rows])
    print(f"{len(rows)} pairs; per-pair catheter IoU mean {iou[:, 0].mean():.3f}/{iou[:, 1].mean():.3f}")
    by_setting(args.data, rows, iou)
    along_catheter(args.data, args.masks, rows, args.long_mm)
    if args.bench:
        by_region(args.bench, args.masks, rows)


if __name__ == "__main__":
    main()
