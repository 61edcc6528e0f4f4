"""Coverage of the spectral radius's 95 % delta-method interval at a lab's sample sizes.

Linear VAR(1) data (eq. 19) with a known J, the model's at two points (Fig. 8's parameters,
alpha 0.42, g 5.8 m/s^2, a_r 0.065 m, tau 0.55 s: radius 0.42, a complex pair; and alpha 0.8,
g 9.81 m/s^2, a_r 0.03 m, tau 0.45 s: radius 0.8), the paper's noise (q_v 0.04 m/s, q_theta
0.05 rad), with or without white measurement noise on (v, theta) (0.03 m/s, 1 deg: the
assumption of ``acf --data``'s trust study when no setup.csv gives the set-up's own). Per size
(trials x impacts per trial) and estimator (jackknifed OLS and lag 2), over ``--sets`` data
sets: how many were fitted, how often the log-scale delta interval covers the true radius, the
median bias against the 16-84 % spread, and the trust study's verdict by its rule (coverage at
least 90 %, |median bias| at most a quarter of the spread): where it is "trusted", ``acf
--data`` and ``study`` give the interval below the fixed minimum of 200 pairs / 1200 triples.
The table in docs/data-workflow.md is this script's output::

    python benchmarks/interval_coverage.py --sets 2000
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from bounce_cli.analysis.stochastic import paper_noise_covariance
from bounce_cli.analysis.var_stacked import (
    log_radius_se,
    simulate_panels,
    stacked_fit,
)
from bounce_cli.model.linear import jacobian, spectral_radii_2x2 as spectral_radii
from bounce_cli.model.params import ModelParams

SIZES = ["3x30", "3x60", "5x30", "5x60", "10x30", "10x60"]
CASES = {"radius 0.42 (Fig. 8)": ModelParams(0.42, 5.8, 0.065, 0.55),
         "radius 0.8": ModelParams(0.8, 9.81, 0.03, 0.45)}


def row(jac, noise, meas, lengths, method, sets, rng) -> dict:
    truth = float(spectral_radii(jac))
    panels = simulate_panels(jac, noise, lengths, sets, rng, measurement_sd=meas)
    fit = stacked_fit(panels, lengths, method, jackknife=True)
    jac_hat, cov = fit.jacobian[fit.identified], fit.cov_vec[fit.identified]
    value = spectral_radii(jac_hat)
    half = np.minimum(1.959964 * log_radius_se(jac_hat, cov), 700.0)
    inside = (value * np.exp(-half) <= truth) & (truth <= value * np.exp(half))
    q16, med, q84 = np.percentile(value, [16, 50, 84])
    coverage = float(inside.mean())
    trusted = coverage >= 0.90 and abs(med - truth) <= 0.25 * (q84 - q16)
    return {"fitted": len(value), "coverage": coverage, "bias": med - truth,
            "spread": q84 - q16, "trusted": trusted}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=int, default=2000)
    parser.add_argument("--sizes", default=",".join(SIZES))
    parser.add_argument("--seed", type=int, default=2026)
    args = parser.parse_args()
    noise = paper_noise_covariance(0.04, 0.05)
    rng = np.random.default_rng(args.seed)
    print("| J | measurement noise | trials x impacts | estimator | fitted | coverage | "
          "median bias / 16-84 % spread | trusted |")
    print("|---|---|---|---|---|---|---|---|")
    start = time.perf_counter()
    for name, params in CASES.items():
        jac = jacobian(params)
        for meas_name, meas in (("none", np.zeros(2)),
                                ("0.03 m/s, 1 deg", np.array([0.03, math.radians(1.0)]))):
            for size in args.sizes.split(","):
                trials, per = (int(x) for x in size.split("x"))
                for method in ("ols", "lag2"):
                    r = row(jac, noise, meas, [per] * trials, method, args.sets, rng)
                    print(f"| {name} | {meas_name} | {trials} x {per} | {method} | "
                          f"{r['fitted']} | {r['coverage']:.1%} | {r['bias']:+.3f} / "
                          f"{r['spread']:.3f} | {'yes' if r['trusted'] else 'no'} |",
                          flush=True)
    print(f"\n{args.sets} data sets per row, {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
