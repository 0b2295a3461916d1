"""What the extra blobs are in the views `hnet eval` found no single catheter in.

For each pair of an `hnet eval --predictions` file without a physics estimate, and each of its
views whose predicted mask (`--masks`) holds more than one blob at half coverage, prints the
largest blob (the catheter) and every other blob of at least 8 px and a tenth of it: its size
(pixels), its share on the true mask (from the error map: white found, blue missed), its gap to
the catheter and its distance to the catheter's tip (pixels), its highest probability, and what
the centreline's blob rule makes of it (crates/hnet-twin/src/reconstruction/centreline/trace.rs,
`catheter_blob`): "beside" (set aside: smaller than half the catheter and not beyond its tip),
or "continues" (beyond the tip or as large: the view stays an error). A catheter blob that does
not touch the border is an error too. docs/log/2026-12-05-blobs-beside-the-catheter.md quotes it.

Usage:
  hnet eval --weights W --data D --split train --predictions p.csv --masks m/
  python bench/mask_blobs.py --predictions p.csv --masks m/
Needs numpy, scipy and Pillow. Pixels are the masks' (the network's input size).
"""

import argparse
import csv
from collections import deque

import numpy as np
from PIL import Image
from scipy import ndimage

# The rule's settings (CentrelineSettings::set_aside_fraction, beyond_tip_px).
SET_ASIDE_FRACTION = 0.5
BEYOND_TIP_PX = 4.0
EIGHT = np.ones((3, 3))


def far_point(inside, sources):
    """The pixel of `inside` farthest from `sources` along 8-connected paths inside it."""
    height, width = inside.shape
    steps = -np.ones(inside.shape, int)
    queue = deque(sources)
    for s in sources:
        steps[s] = 0
    far = sources[0]
    while queue:
        y, x = queue.popleft()
        if steps[y, x] > steps[far]:
            far = (y, x)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                ny, nx = y + dy, x + dx
                if 0 <= ny < height and 0 <= nx < width and inside[ny, nx] and steps[ny, nx] < 0:
                    steps[ny, nx] = steps[y, x] + 1
                    queue.append((ny, nx))
    return far


def view_blobs(probability, truth):
    """(catheter px, touches border, [(px, on truth, gap, to tip, max p, verdict)]) or None."""
    labels, count = ndimage.label(probability >= 0.5, structure=EIGHT)
    if count < 2:
        return None
    sizes = ndimage.sum(np.ones_like(probability), labels, range(1, count + 1))
    order = np.argsort(-sizes)
    largest = sizes[order[0]]
    others = [k for k in order[1:] if sizes[k] >= max(8, 0.1 * largest)]
    if not others:
        return None
    catheter = labels == order[0] + 1
    height, width = catheter.shape
    border = [
        (y, x)
        for y, x in zip(*np.nonzero(catheter))
        if y in (0, height - 1) or x in (0, width - 1)
    ]
    gap_to_catheter = ndimage.distance_transform_edt(~catheter)
    tip = np.array(far_point(catheter, border)) if border else None
    rows = []
    for k in others:
        blob = labels == k + 1
        gap = gap_to_catheter[blob].min()
        to_tip = np.sqrt(((np.argwhere(blob) - tip) ** 2).sum(-1)).min() if border else np.nan
        beside = (
            bool(border)
            and sizes[k] < SET_ASIDE_FRACTION * largest
            and to_tip > gap + BEYOND_TIP_PX
        )
        rows.append(
            (int(sizes[k]), truth[blob].mean(), gap, to_tip, probability[blob].max(),
             "beside" if beside else "continues")
        )
    return int(largest), bool(border), rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--predictions", required=True, help="hnet eval --predictions CSV")
    parser.add_argument("--masks", required=True, help="hnet eval --masks folder")
    args = parser.parse_args()
    with open(args.predictions, newline="") as f:
        pairs = list(csv.DictReader(f))
    lost = [p["id"] for p in pairs if p["fx_physics"] == ""]
    print(f"{len(pairs)} pairs, {len(lost)} without a physics estimate")
    views = resolved = 0
    for pair in lost:
        for view in "ab":
            probability = np.asarray(
                Image.open(f"{args.masks}/{pair}_predicted_mask_{view}.png").convert("L"), float
            ) / 255
            errors = np.asarray(Image.open(f"{args.masks}/{pair}_errors_{view}.png").convert("RGB"))
            white = (errors[..., 0] > 128) & (errors[..., 1] > 128)
            blue = (errors[..., 2] > 128) & (errors[..., 0] < 128)
            found = view_blobs(probability, white | blue)
            if found is None:
                continue
            largest, touches_border, rows = found
            views += 1
            ok = touches_border and all(r[-1] == "beside" for r in rows)
            resolved += ok
            print(
                f"{pair} {view}: catheter {largest} px"
                + ("" if touches_border else " (off the border: an error)")
                + " | "
                + "; ".join(
                    f"{px} px, {on:.2f} on the true mask, gap {gap:.1f}, to tip {tip:.1f}, "
                    f"p max {p:.2f}, {verdict}"
                    for px, on, gap, tip, p, verdict in rows
                )
            )
    print(f"{views} views with several blobs; the rule sets every other blob aside in {resolved}")


if __name__ == "__main__":
    main()
