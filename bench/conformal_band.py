#!/usr/bin/env python3
"""How often a split-conformal 90 % interval's measured coverage lands in 85-95 % by chance alone.

Issue #36 asks that on every suite set and axis the nominal 90 % interval cover 85-95 % of the
true forces. The intervals are split-conformal (`conformal_quantile` in
crates/hnet-twin/src/reconstruction/physics_force.rs): the ceil(0.9 (n + 1))-th smallest of n
calibration scores. Even when the scores are exchangeable (the interval exactly calibrated in
expectation), its coverage given the calibration pairs is random, Beta(k, n + 1 - k) with
k = ceil(0.9 (n + 1)) (Vovk 2012; Angelopoulos and Bates 2021, section 3.2), and the share measured
on m evaluated pairs adds binomial noise. This script gives the probability that the measured
share lies in [low, high] for n calibration and m evaluated pairs, by exact summation over the
binomial and numerical integration over the Beta density (standard library only).

Usage: python bench/conformal_band.py [--level 0.9] [--band 0.85 0.95] N:M [N:M ...]
e.g.   python bench/conformal_band.py 60:480 120:480 240:480 60:195
"""

import argparse
import math


def beta_log_pdf(x: float, a: float, b: float) -> float:
    return (
        (a - 1) * math.log(x)
        + (b - 1) * math.log1p(-x)
        + math.lgamma(a + b)
        - math.lgamma(a)
        - math.lgamma(b)
    )


def binomial_band(m: int, p: float, low: int, high: int) -> float:
    """P(low <= Binomial(m, p) <= high)."""
    if p <= 0.0 or p >= 1.0:
        return float(low <= m * p <= high)
    lp, lq = math.log(p), math.log1p(-p)
    total = 0.0
    for j in range(low, high + 1):
        total += math.exp(math.lgamma(m + 1) - math.lgamma(j + 1) - math.lgamma(m - j + 1) + j * lp + (m - j) * lq)
    return total


def in_band(n: int, m: int, level: float, band: tuple[float, float], steps: int = 4000) -> tuple[float, float, float]:
    """(P(measured share in band), the coverage's mean, its standard deviation over calibrations)."""
    k = min(math.ceil(level * (n + 1)), n)
    a, b = k, n + 1 - k
    low, high = math.ceil(band[0] * m - 1e-9), math.floor(band[1] * m + 1e-9)
    # Midpoint rule over the Beta density on (0, 1).
    total = 0.0
    for i in range(steps):
        x = (i + 0.5) / steps
        total += math.exp(beta_log_pdf(x, a, b)) * binomial_band(m, x, low, high) / steps
    mean = a / (a + b)
    sd = math.sqrt(a * b / ((a + b) ** 2 * (a + b + 1)))
    # The measured share's spread: the calibration's and the evaluation's together.
    spread = math.sqrt(sd**2 + mean * (1 - mean) / m)
    return total, mean, spread


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sizes", nargs="+", help="N:M, calibration and evaluated pairs")
    parser.add_argument("--level", type=float, default=0.9)
    parser.add_argument("--band", type=float, nargs=2, default=(0.85, 0.95))
    args = parser.parse_args()
    print("| calibration pairs | evaluated pairs | expected coverage | its spread (sd) | P(measured in band) |")
    print("| --- | --- | --- | --- | --- |")
    for size in args.sizes:
        n, m = (int(v) for v in size.split(":"))
        p, mean, spread = in_band(n, m, args.level, tuple(args.band))
        print(f"| {n} | {m} | {100 * mean:.1f} % | {100 * spread:.1f} points | {100 * p:.0f} % |")


if __name__ == "__main__":
    main()
