"""Benchmark of the Fig. 4 basin (a script, not a test).

Times ``classify_grid`` on an N x N grid of the paper's Fig. 4 (theta0 0..360 deg, v0 0..10
m/s, the paper's parameters and stopping conditions) with one job and with all cores, with the
compiled kernel (``engine.compiled``, numba, in threads; when installed) and the numpy one (in
worker processes), checking that both give identical outcomes and impact counts, and the
paper's method -- a per-point Python loop around ``scipy.optimize.brentq`` for every impact
(``engine.reference.classify_point_brentq``, bracketed by a first-root scan) -- on a random
subsample of the grid, extrapolated to the whole grid. Prints points per second and ratios.
With ``--memory-size M`` it also runs ``bounce basin`` on an M x M grid (CSV and figures
included) in a subprocess and reports its peak resident memory.

With ``--end-to-end`` it times the whole command -- ``bounce basin`` on the N x N grid in a
subprocess: start-up, classification, basin.csv, figures -- with one job and with ``--jobs``,
against the plain single-thread vectorised numpy kernel of the same map alone
(``benchmarks/plain_kernel.py``), each ``--repeat`` times, and reports the minimum of each (the
machine may be shared: the minimum is the run least disturbed). ``--scaling 250,500,1000``
does the same end-to-end timing at several grid sizes; ``--numpy-kernel`` adds the command
with ``BOUNCE_KERNEL=numpy`` (what a user without numba gets).

    python benchmarks/basin.py                       # 1000 x 1000, 1000-point subsample
    python benchmarks/basin.py --size 200 --subsample 200
    python benchmarks/basin.py --skip-grid --end-to-end --repeat 5 --numpy-kernel
    python benchmarks/basin.py --skip-grid --scaling 250,500,1000,2000 --repeat 3
    python benchmarks/basin.py --skip-grid --memory-size 4000 --memory-format npz
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bounce_cli.runtime import parallel  # noqa: E402
from bounce_cli.analysis.classify import (  # noqa: E402
    OUTCOMES,
    ClassifySettings,
    classify_grid,
    compiled_kernel_available,
)
from bounce_cli.model.params import ModelParams  # noqa: E402
from bounce_cli.model.reference import classify_point_brentq  # noqa: E402
from bounce_cli.experiments.basin import COMPILED_MIN_POINTS  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from plain_kernel import classify_plain  # noqa: E402

PARAMS = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
SETTINGS = ClassifySettings(max_iterations=100, tolerance=1e-3, min_hop_s=1e-3)


def grid(n: int):
    theta, v = np.meshgrid(np.deg2rad(np.linspace(0, 360, n)), np.linspace(0, 10, n))
    return theta.ravel(), v.ravel()


def time_grid(theta, v, jobs: int, kernel: str):
    """classify_grid as ``bounce basin`` runs it: the compiled kernel in threads, the numpy
    one in worker processes (BOUNCE_KERNEL=numpy)."""
    compiled = kernel == "compiled"
    os.environ["BOUNCE_KERNEL"] = "auto" if compiled else "numpy"
    if compiled:  # load numba and the cached kernel first: start-up, timed end to end below
        classify_grid(theta[:4], v[:4], PARAMS, SETTINGS)
    t0 = time.perf_counter()  # pool start included, as a user pays it
    with parallel.executor(jobs, threads=compiled) as executor:
        res = classify_grid(theta, v, PARAMS, SETTINGS, map=executor.map,
                            workers=executor.workers)
    return time.perf_counter() - t0, res


def time_reference(theta, v, m: int, seed: int, fast):
    rng = np.random.default_rng(seed)
    pick = rng.choice(theta.size, size=min(m, theta.size), replace=False)
    t0 = time.perf_counter()
    ref = [classify_point_brentq(theta[i], v[i], PARAMS) for i in pick]
    elapsed = time.perf_counter() - t0
    agree = None
    if fast is not None:
        names = fast.names()
        agree = sum(r == (names[i], int(fast.iterations[i])) for r, i in zip(ref, pick))
    return elapsed, len(pick), agree


def basin_command(m: int, jobs: int, out: str, fmt: str = "csv") -> list[str]:
    return [sys.executable, "-m", "bounce_cli", "basin", "--quiet", "--jobs", str(jobs),
            "--set", f"grid.theta0_deg.num={m}", "--set", f"grid.v0_m_s.num={m}",
            "--set", f"output.format={fmt}", "--out", out, "--force"]


def memory_run(m: int, jobs: int, fmt: str) -> None:
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        subprocess.run(basin_command(m, jobs, out, fmt), cwd=ROOT, check=True)
        wall = time.perf_counter() - t0
        peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        size = (Path(out) / f"basin.{fmt}").stat().st_size
    print(f"bounce basin {m} x {m} (--jobs {jobs}, basin.{fmt} + figures): {wall:.1f} s, "
          f"peak RSS of the largest process {peak_kib / 1024:.0f} MiB, "
          f"basin.{fmt} {size / 1e6:.0f} MB")


def time_command(m: int, jobs: int, repeat: int, kernel: str = "auto") -> list[float]:
    """Wall times of ``bounce basin`` m x m (a fresh process each time: start-up included);
    ``kernel`` is BOUNCE_KERNEL (auto: the compiled kernel when numba is installed)."""
    times = []
    env = {**os.environ, "BOUNCE_KERNEL": kernel}
    with tempfile.TemporaryDirectory() as out:
        for _ in range(repeat):
            t0 = time.perf_counter()
            subprocess.run(basin_command(m, jobs, out), cwd=ROOT, check=True, env=env)
            times.append(time.perf_counter() - t0)
    return times


def time_plain(m: int, repeat: int) -> list[float]:
    theta, v = grid(m)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        classify_plain(theta, v)
        times.append(time.perf_counter() - t0)
    return times


def runs(times: list[float]) -> str:
    return f"min {min(times):.2f} s of {len(times)} ({', '.join(f'{t:.2f}' for t in times)})"


def end_to_end(sizes: list[int], jobs: int, repeat: int, numpy_kernel: bool,
               numba_dispatcher: bool = False) -> None:
    """``bounce basin`` end to end with 1 and ``jobs`` jobs (and, with ``numpy_kernel``, with
    BOUNCE_KERNEL=numpy; with ``numba_dispatcher``, BOUNCE_KERNEL=numba) against the plain
    kernel alone, runs interleaved (so that a busy spell of a shared machine hits all of
    them alike)."""
    for m in sizes:
        if not compiled_kernel_available():
            kernel = "numpy (numba missing)"
        elif m * m < COMPILED_MIN_POINTS:
            kernel = f"numpy (below {COMPILED_MIN_POINTS:,} points)"
        else:
            kernel = "compiled (numba)"
        plain: list[float] = []
        runs_by: dict[str, list[float]] = {}
        variants = [(f"--jobs 1, {kernel} kernel", 1, "auto")]
        if jobs > 1:
            variants.append((f"--jobs {jobs}, {kernel} kernel", jobs, "auto"))
        if numba_dispatcher and kernel == "compiled (numba)":
            variants.append((f"--jobs {jobs}, BOUNCE_KERNEL=numba (numba's dispatcher, "
                             "the route before model.native)", jobs, "numba"))
        if numpy_kernel:
            variants.append((f"--jobs {jobs}, BOUNCE_KERNEL=numpy", jobs, "numpy"))
        for _ in range(repeat):
            plain += time_plain(m, 1)
            for label, j, k in variants:
                runs_by.setdefault(label, []).extend(time_command(m, j, 1, k))
        print(f"{m} x {m}: plain numpy kernel alone {runs(plain)}")
        for label, times in runs_by.items():
            paired = np.sort(np.array(plain) / np.array(times))  # each round's own ratio
            print(f"{m} x {m}: bounce basin end to end {label}: {runs(times)}: "
                  f"{min(plain) / min(times):.2f}x the plain kernel's speed (minimum against "
                  f"minimum; each round's ratio: median {np.median(paired):.2f}x, quartiles "
                  f"{np.quantile(paired, 0.25):.2f}-{np.quantile(paired, 0.75):.2f}x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1000, help="grid side N (N x N points)")
    ap.add_argument("--subsample", type=int, default=1000, help="points for the brentq loop")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="'all cores' jobs")
    ap.add_argument("--seed", type=int, default=0, help="seed of the subsample")
    ap.add_argument("--skip-grid", action="store_true", help="only the memory run")
    ap.add_argument("--memory-size", type=int, default=0, help="also run bounce basin M x M")
    ap.add_argument("--memory-format", default="csv", choices=["csv", "npz", "parquet"],
                    help="output.format of the memory run")
    ap.add_argument("--end-to-end", action="store_true",
                    help="time bounce basin N x N end to end against the plain kernel")
    ap.add_argument("--scaling", default="", help="comma-separated sizes for --end-to-end")
    ap.add_argument("--repeat", type=int, default=3, help="repeats of each end-to-end timing")
    ap.add_argument("--numpy-kernel", action="store_true",
                    help="also time bounce basin end to end with BOUNCE_KERNEL=numpy")
    ap.add_argument("--numba-dispatcher", action="store_true",
                    help="also time bounce basin end to end with BOUNCE_KERNEL=numba (the "
                         "kernel through numba's dispatcher, not its saved machine code)")
    args = ap.parse_args()

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"{platform.system()} {platform.release()}, Python {platform.python_version()}, "
          f"numpy {np.__version__}")
    if not args.skip_grid:
        theta, v = grid(args.size)
        n = theta.size
        kernels = ["compiled", "numpy"] if compiled_kernel_available() else ["numpy"]
        first = None
        for kernel in kernels:
            t1, res = time_grid(theta, v, 1, kernel)
            print(f"grid {args.size} x {args.size} = {n:,} points, {kernel} kernel, --jobs 1: "
                  f"{t1:.2f} s, {n / t1:,.0f} points/s")
            if first is None:
                first = (t1, res)
                fractions = np.bincount(res.outcome, minlength=4) / n
                print("  fractions: " + ", ".join(
                    f"{o} {f:.4f}" for o, f in zip(OUTCOMES, fractions))
                    + f"; max impacts {res.iterations.max()}")
            else:
                same = np.array_equal(res.outcome, first[1].outcome) and np.array_equal(
                    res.iterations, first[1].iterations)
                print(f"  identical outcomes and impact counts to the compiled kernel: {same}")
            if args.jobs > 1:
                tj, resj = time_grid(theta, v, args.jobs, kernel)
                same = np.array_equal(res.outcome, resj.outcome) and np.array_equal(
                    res.iterations, resj.iterations)
                print(f"  --jobs {args.jobs}: {tj:.2f} s, {n / tj:,.0f} points/s, "
                      f"speed-up {t1 / tj:.2f}x, identical results: {same}")
        t1, res = first
        tr, m, agree = time_reference(theta, v, args.subsample, args.seed, res)
        per_point = tr / m
        print(f"paper's method (per-point brentq loop): {m} points in {tr:.2f} s, "
              f"{1 / per_point:,.0f} points/s, extrapolated to the grid: {per_point * n:,.0f} s "
              f"({per_point * n / 3600:.2f} h); agrees with the fast classifier on {agree}/{m}")
        print(f"ratio, {kernels[0]} kernel --jobs 1 vs brentq loop: "
              f"{per_point * n / t1:,.0f}x")
    if args.end_to_end or args.scaling:
        sizes = [int(x) for x in args.scaling.split(",")] if args.scaling else [args.size]
        end_to_end(sizes, args.jobs, args.repeat, args.numpy_kernel, args.numba_dispatcher)
    if args.memory_size:
        memory_run(args.memory_size, args.jobs, args.memory_format)


if __name__ == "__main__":
    main()
