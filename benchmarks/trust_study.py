"""The trust study of acf --data (``trust_frame``: 6 sizes and the data's own, 200
repetitions, OLS and lag 2, jackknifed) with its stacked fits, beside the reference route:
the six sizes' fits one by one through ``fit_var1`` (the route before issue 35), in one run::

    python benchmarks/trust_study.py
"""

from __future__ import annotations

import time
import types

import numpy as np

from bounce_cli.analysis.var_fit import fit_var1
from bounce_cli.experiments.data_side import AcfDataBlock, MeasurementNoise, trust_frame
from bounce_cli.model.params import ModelError, ModelParams


def main() -> None:
    params = ModelParams(0.42, 5.8, 0.065, 0.55)
    block = AcfDataBlock()
    config = types.SimpleNamespace(data_analysis=block)
    segments = [(None, np.zeros(108)) for _ in range(10)]
    noise = MeasurementNoise(0.03, float(np.radians(1.0)), "assumed")
    options = types.SimpleNamespace(progress=types.SimpleNamespace(advance=lambda n: None))
    start = time.perf_counter()
    trust_frame(params, 0.04, 0.05, config, segments, options, noise)
    stacked = time.perf_counter() - start
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    for total in block.trust_bounces:
        n_trials = max(1, round(total / 108))
        series = rng.standard_normal((200 * n_trials, 108, 2)) * 0.05
        for method in ("ols", "lag2"):
            for r in range(200):
                try:
                    fit_var1(list(series[r * n_trials:(r + 1) * n_trials]), method
                             ).eigen_summary()
                except ModelError:
                    pass
    one_by_one = time.perf_counter() - start
    print(f"trust study: stacked {stacked:.2f} s (6 sizes and the data's own); one by one "
          f"{one_by_one:.2f} s (the 6 sizes only): {one_by_one / stacked:.1f}x")


if __name__ == "__main__":
    main()
