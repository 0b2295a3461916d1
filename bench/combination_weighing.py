"""Other ways to weigh the force head against the physics estimate, on what `hnet eval` wrote.

`ForceCombination` (crates/hnet-twin/src/reconstruction/physics_force.rs) weighs the two per axis
by inverse error variance and takes their errors as independent. This script measures whether
anything that drops those assumptions does better: each variant is calibrated on the first
predictions file's pairs and scored (R² per axis) on the second's, as `hnet eval --calibration`
does. docs/results.md, "The combined estimate", quotes its table.

  hnet eval --weights W --data C --split val --calibration D --predictions cal.csv
  hnet eval --weights W --data D --split train --calibration C --predictions test.csv
  python bench/combination_weighing.py cal.csv test.csv

Needs numpy only. Forces in newtons; the physics estimate's standard errors are the rod fit's
(`RodFit::force_sd_n`), its correlations between axes the same fit's (`force_correlation`).
"""

import argparse
import csv

import numpy as np

AXES = ("fx", "fy", "fz")
# A normal's median |z|: turns a median absolute deviation into a standard deviation.
NORMAL_MEDIAN_ABS = 0.6744897501960817


def load(path):
    """The pairs of a predictions file with a network force and a physics estimate with its
    standard error and correlations, as arrays of shape (pairs, 3)."""
    rows = [
        r
        for r in csv.DictReader(open(path))
        if r["fx_pred"] and r["fx_physics_sd"] and r.get("physics_corr_xy")
    ]
    if not rows:
        raise SystemExit(f"{path}: no pair with a network force, a physics estimate and its correlations")

    def columns(names):
        return np.array([[float(r[n]) for n in names] for r in rows])

    return {
        "truth": columns(AXES),
        "network": columns([a + "_pred" for a in AXES]),
        "physics": columns([a + "_physics" for a in AXES]),
        "sd": columns([a + "_physics_sd" for a in AXES]),
        "corr": columns(["physics_corr_xy", "physics_corr_xz", "physics_corr_yz"]),
        "combined": columns([a + "_combined" for a in AXES]) if rows[0]["fx_combined"] else None,
    }


def r2(estimate, truth):
    return 1 - ((estimate - truth) ** 2).sum(0) / ((truth - truth.mean(0)) ** 2).sum(0)


def physics_scale(cal):
    """`ForceCombination::physics_sd_scale`: the median |error / standard error| over all axes."""
    z = np.abs(cal["physics"] - cal["truth"]) / cal["sd"]
    return np.median(z) / NORMAL_MEDIAN_ABS


def per_axis(cal, pairs, scale_per_axis=False):
    """Today's rule: per axis, inverse variance, the errors independent."""
    network_var = ((cal["network"] - cal["truth"]) ** 2).mean(0)
    z = np.abs(cal["physics"] - cal["truth"]) / cal["sd"]
    scale = np.median(z, 0) / NORMAL_MEDIAN_ABS if scale_per_axis else physics_scale(cal)
    physics_var = (pairs["sd"] * scale) ** 2
    w = network_var / (network_var + physics_var)
    return w * pairs["physics"] + (1 - w) * pairs["network"]


def correlation_matrix(r):
    xy, xz, yz = r
    return np.array([[1, xy, xz], [xy, 1, yz], [xz, yz, 1]])


def generalised(cal, pairs, physics_corr, cross=False):
    """Each estimate with a full 3x3 error covariance: the network's from the calibration pairs,
    the physics estimate's its scaled standard errors with `physics_corr(i)` between axes; with
    `cross`, also the covariance between the two estimates' errors (a joint 6x6 least squares)."""
    network_err = cal["network"] - cal["truth"]
    network_cov = network_err.T @ network_err / len(network_err)
    scale = physics_scale(cal)
    z = np.clip((cal["physics"] - cal["truth"]) / cal["sd"], -5 * scale, 5 * scale)
    cross_per_sd = network_err.T @ z / len(z)
    out = []
    for i in range(len(pairs["truth"])):
        d = np.diag(pairs["sd"][i] * scale)
        physics_cov = d @ physics_corr(i) @ d
        y = np.concatenate([pairs["network"][i], pairs["physics"][i]])
        c = cross_per_sd @ np.diag(pairs["sd"][i]) if cross else np.zeros((3, 3))
        cov = np.block([[network_cov, c], [c.T, physics_cov]])
        h = np.vstack([np.eye(3), np.eye(3)])
        inv = np.linalg.inv(cov)
        out.append(np.linalg.solve(h.T @ inv @ h, h.T @ inv @ y))
    return np.array(out)


def population_corr(cal):
    scale = physics_scale(cal)
    z = np.clip((cal["physics"] - cal["truth"]) / cal["sd"], -5 * scale, 5 * scale)
    return np.corrcoef(z.T)


def stacking(cal, pairs):
    """Least squares of the true force on both estimates' six components and a constant."""
    def features(d):
        return np.hstack([d["network"], d["physics"], np.ones((len(d["truth"]), 1))])

    coefficients, *_ = np.linalg.lstsq(features(cal), cal["truth"], rcond=None)
    return features(pairs) @ coefficients


def fit_correlations(cal, pairs, shrink):
    return generalised(cal, pairs, lambda i: correlation_matrix(pairs["corr"][i] * shrink))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("calibration", help="predictions CSV of the calibration pairs")
    parser.add_argument("test", help="predictions CSV of the pairs to score")
    args = parser.parse_args()
    cal, test = load(args.calibration), load(args.test)
    shrinks = np.round(np.linspace(0, 1, 11), 2)
    on_cal = [r2(fit_correlations(cal, cal, k), cal["truth"]).mean() for k in shrinks]
    chosen = shrinks[int(np.argmax(on_cal))]
    population = population_corr(cal)
    rows = [
        ("force head", test["network"]),
        ("physics estimate", test["physics"]),
        ("per axis, one scale (`ForceCombination`)", per_axis(cal, test)),
        ("per axis, a scale per axis", per_axis(cal, test, scale_per_axis=True)),
        ("3x3 covariances, the calibration pairs' correlations",
         generalised(cal, test, lambda i: population)),
        ("joint 6x6, with the two estimates' cross-covariance",
         generalised(cal, test, lambda i: population, cross=True)),
        ("linear stacking of both estimates", stacking(cal, test)),
        ("3x3, the fit's own correlations (shrink 1)", fit_correlations(cal, test, 1.0)),
        (f"3x3, the fit's own correlations (shrink {chosen:.1f}, chosen on calibration)",
         fit_correlations(cal, test, chosen)),
    ]
    print(f"{len(cal['truth'])} calibration pairs, {len(test['truth'])} scored pairs\n")
    print("| weighing | R² Fx / Fy / Fz (mean) |\n| --- | --- |")
    for name, estimate in rows:
        r = r2(estimate, test["truth"])
        print(f"| {name} | {r[0]:.3f} / {r[1]:.3f} / {r[2]:.3f} ({r.mean():.3f}) |")
    print("\nshrink of the fit's correlations: mean R² on calibration / scored pairs")
    for k, c in zip(shrinks, on_cal):
        t = r2(fit_correlations(cal, test, k), test["truth"]).mean()
        print(f"  {k:.1f}: {c:.3f} / {t:.3f}")
    print("\nthe fit's correlations per pair, mean |r| (x-y, x-z, y-z):",
          np.round(np.abs(test["corr"]).mean(0), 2),
          "\nthe calibration pairs' normalised errors, correlation (x-y, x-z, y-z):",
          np.round([population[0, 1], population[0, 2], population[1, 2]], 2))


if __name__ == "__main__":
    main()
