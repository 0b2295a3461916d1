"""Which way the physics estimate's force error points, against the catheter's shape.

Reads an `hnet eval --predictions` file and the twin records of the dataset it scored, and
splits each pair's physics-estimate error (estimate minus truth, newtons, world frame) into its
component along the flexible section's chord (the unit vector from the section's base to its tip,
from the record's true centreline) and the rest. It prints how the errors correlate between axes,
the error's principal direction and its share of the variance, how well that direction lines up
with the chord, and the root-mean-square error and true force along and across the chord. Last,
it weighs the force head against the physics estimate per axis by inverse error variance, once in
the world axes and once in each pair's chord frame (the chord and two axes across it), scored by
5-fold cross-validation over the file's pairs. docs/log/2026-12-05-weighing-the-combination.md quotes it.

  hnet eval --weights W --data D --split train [--oracle] --predictions pred.csv
  python bench/force_error_direction.py pred.csv D

Needs numpy only.
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np

AXES = ("fx", "fy", "fz")


def chord(dataset, pair_id):
    """The unit vector from the flexible section's base to its tip (world frame)."""
    record = json.loads((Path(dataset) / "samples" / f"{pair_id}.json").read_text())["record"]
    centreline = np.array(record["centreline_mm"])
    direction = centreline[-1] - centreline[0]
    return direction / np.linalg.norm(direction)


def chord_frame(direction):
    """Rows: the chord and two unit vectors across it."""
    across = np.cross(direction, [0.0, 1.0, 0.0])
    if np.linalg.norm(across) < 1e-6:
        across = np.cross(direction, [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    return np.array([direction, across, np.cross(direction, across)])


def r2(estimate, truth):
    return 1 - ((estimate - truth) ** 2).sum(0) / ((truth - truth.mean(0)) ** 2).sum(0)


def weighed(truth, network, physics, folds):
    """Per axis, inverse error variance with the variances of the other folds' pairs."""
    out = np.zeros_like(truth)
    for fold in folds:
        rest = np.setdiff1d(np.arange(len(truth)), fold)
        network_var = ((network[rest] - truth[rest]) ** 2).mean(0)
        physics_var = ((physics[rest] - truth[rest]) ** 2).mean(0)
        w = network_var / (network_var + physics_var)
        out[fold] = w * physics[fold] + (1 - w) * network[fold]
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("predictions", help="hnet eval's predictions CSV")
    parser.add_argument("dataset", help="the dataset folder it scored (for the twin records)")
    args = parser.parse_args()
    rows = [r for r in csv.DictReader(open(args.predictions)) if r["fx_physics"]]
    if not rows:
        raise SystemExit(f"{args.predictions}: no pair with a physics estimate")
    truth = np.array([[float(r[a]) for a in AXES] for r in rows])
    physics = np.array([[float(r[a + "_physics"]) for a in AXES] for r in rows])
    chords = np.array([chord(args.dataset, r["id"]) for r in rows])
    error = physics - truth

    corr = np.corrcoef(error.T)
    values, vectors = np.linalg.eigh(np.cov(error.T))
    principal = vectors[:, -1]
    along = (error * chords).sum(1)
    across = np.linalg.norm(error - along[:, None] * chords, axis=1)
    truth_along = (truth * chords).sum(1)
    truth_across = np.linalg.norm(truth - truth_along[:, None] * chords, axis=1)
    unit_error = error / np.linalg.norm(error, axis=1, keepdims=True)
    alignment = np.abs((unit_error * chords).sum(1))

    def rms(x):
        return float(np.sqrt((x**2).mean()))

    print(f"{len(rows)} pairs with a physics estimate")
    print(f"error correlation x-y {corr[0, 1]:.2f}, x-z {corr[0, 2]:.2f}, y-z {corr[1, 2]:.2f}")
    print(f"error's principal direction {np.round(principal, 3)}: "
          f"{values[-1] / values.sum():.1%} of its variance")
    print(f"mean chord {np.round(chords.mean(0), 3)}; |cos(error, chord)| median {np.median(alignment):.3f}")
    print(f"error rms along the chord {rms(along):.4f} N, across it {rms(across):.4f} N")
    print(f"true force rms along the chord {rms(truth_along):.4f} N, across it {rms(truth_across):.4f} N")

    with_head = [i for i, r in enumerate(rows) if r["fx_pred"]]
    if len(with_head) < 10:
        return
    network = np.array([[float(rows[i][a + "_pred"]) for a in AXES] for i in with_head])
    t, p = truth[with_head], physics[with_head]
    frames = np.array([chord_frame(chords[i]) for i in with_head])
    folds = np.array_split(np.random.default_rng(0).permutation(len(with_head)), 5)

    def to_frame(x):
        return np.einsum("nij,nj->ni", frames, x)

    in_frame = weighed(to_frame(t), to_frame(network), to_frame(p), folds)
    for name, estimate in (
        ("world axes", weighed(t, network, p, folds)),
        ("chord frame", np.einsum("nji,nj->ni", frames, in_frame)),
    ):
        r = r2(estimate, t)
        print(f"weighed per axis in the {name} (5-fold): R² {r[0]:.3f} / {r[1]:.3f} / {r[2]:.3f} ({r.mean():.3f})")


if __name__ == "__main__":
    main()
