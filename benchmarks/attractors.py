"""Benchmark of ``bounce attractors``' labelling against today's basin (a script, not a test).

Times, side by side in one run, on an N x N grid of the paper's Fig. 4 (theta0 0..360 deg, v0
0..10 m/s, the paper's parameters): ``analysis.attractors.find_attractors`` (discovery on a
sample, then the recurrence labelling of every start, numpy, one process) and the basin's
``classify_batch`` with the numpy kernel and with the compiled one (numba) where installed,
and checks that the period-1 basin, sticking and below-the-racket are the same starts. Each
route runs ``--repeat`` times; the minimum is reported (the machine may be shared).

    python benchmarks/attractors.py                 # 1000 x 1000
    python benchmarks/attractors.py --size 400 --repeat 3
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from bounce_cli.analysis.attractors import STICKING, BELOW_RACKET, find_attractors
from bounce_cli.analysis.classify import (BELOW_RACKET as C_BELOW, PERIOD1, STICKING as
                                          C_STICKING, classify_batch,
                                          compiled_kernel_available, load_compiled_kernel)
from bounce_cli.paper.values import FIG3_MODEL


def best(function, repeat: int):
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return min(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    th, vv = np.meshgrid(np.radians(np.linspace(0, 360, args.size)),
                         np.linspace(0, 10, args.size))
    print(f"{args.size} x {args.size} starts, {platform.processor() or platform.machine()}")
    t_att, found = best(lambda: find_attractors(th, vv, FIG3_MODEL), args.repeat)
    t_np, today = best(lambda: classify_batch(th, vv, FIG3_MODEL, kernel="numpy"), args.repeat)
    (p1,) = [a.index for a in found.attractors if a.kind == "periodic" and a.period == 1]
    same = (np.array_equal(found.labels == p1, today.outcome == PERIOD1)
            and np.array_equal(found.labels == STICKING, today.outcome == C_STICKING)
            and np.array_equal(found.labels == BELOW_RACKET, today.outcome == C_BELOW))
    print(f"attractors (recurrence, numpy):  {t_att:7.2f} s  "
          f"({found.impacts.mean():.1f} impacts a start)")
    print(f"basin, numpy kernel:             {t_np:7.2f} s  "
          f"({today.iterations.mean():.1f} impacts a start)  ratio {t_att / t_np:.2f}")
    if compiled_kernel_available():
        load_compiled_kernel()
        t_c, _ = best(lambda: classify_batch(th, vv, FIG3_MODEL, kernel="compiled"),
                      args.repeat)
        print(f"basin, compiled kernel (numba):  {t_c:7.2f} s  ratio {t_att / t_c:.2f}")
    print(f"same period-1 basin, sticking and below-the-racket starts: {same}")


if __name__ == "__main__":
    main()
