"""Throughput of `bounce sweep` (basin points per second per core) and its scaling from 1 to
2 local workers: the bundled alpha x AC sweep, enlarged, run through the experiment (no CLI
start-up, no figure files), each job count ``--repeat`` times, the minimum wall time kept
(the machine may be shared). The tables of every run must be identical.

    python benchmarks/sweep.py                       # 6 x 4 points, 150 x 150 basins
    python benchmarks/sweep.py --points 8 6 --basin 200 --repeat 3
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import matplotlib

matplotlib.use("Agg")

from bounce_cli.runtime.config import bundled_config_path, load_config  # noqa: E402
from bounce_cli.experiments import sweep  # noqa: E402
from bounce_cli.experiments.base import RunOptions  # noqa: E402


def cpu_seconds() -> float:
    """User + system CPU time of this process and its reaped children (the pool's workers)."""
    return sum(getattr(resource.getrusage(who), field)
               for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
               for field in ("ru_utime", "ru_stime"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, nargs=2, default=(6, 4), metavar=("NX", "NY"))
    parser.add_argument("--basin", type=int, default=150, help="basin grid points per axis")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--jobs", type=int, nargs="+", default=(1, 2))
    parser.add_argument("--estimate", action="store_true",
                        help="also the speed-up an idle machine would give: each point timed "
                        "alone, scheduled as LocalPool does (in order, to the first idle "
                        "worker) after the measured pool start")
    args = parser.parse_args()
    nx, ny = args.points
    config = load_config(sweep.SweepConfig, bundled_config_path("sweep"), [
        f"sweep.x.num={nx}", f"sweep.y.num={ny}",
        f"basin.theta0_deg.num={args.basin}", f"basin.v0_m_s.num={args.basin}"])
    basin_points = nx * ny * args.basin**2
    print(f"{nx} x {ny} parameter points, basin {args.basin} x {args.basin}: "
          f"{basin_points:,} basin points; {os.cpu_count()} cores; "
          f"load average {os.getloadavg()[0]:.2f} at start")
    reference = None
    best: dict[int, float] = {}
    for jobs in args.jobs:
        times, cpu = [], []
        for _ in range(args.repeat):
            start, cpu_start = time.perf_counter(), cpu_seconds()
            result = sweep.run(config, RunOptions(jobs=jobs))
            times.append(time.perf_counter() - start)
            cpu.append(cpu_seconds() - cpu_start)
            table = result.frames["sweep.csv"]
            if reference is None:
                reference = table
            assert table.equals(reference), "the tables differ between runs"
        best[jobs] = min(times)
        print(f"--jobs {jobs}: {best[jobs]:.2f} s (runs: "
              f"{', '.join(f'{t:.2f}' for t in times)}), {basin_points / best[jobs]:,.0f} "
              f"basin points/s, {basin_points / best[jobs] / jobs:,.0f} per core; CPU "
              f"{min(cpu):.2f} s (this process and its workers)")
    if 1 in best:
        for jobs, t in best.items():
            if jobs > 1:
                print(f"speed-up 1 -> {jobs} workers: {best[1] / t:.2f}x")
    if args.estimate:
        estimate(config, args.jobs)
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


def estimate(config, job_counts) -> None:
    """Per-point CPU times, one after another in this process, and the makespan of
    LocalPool's schedule for each job count: the speed-up when every worker has a core."""
    from bounce_cli.runtime import parallel
    from bounce_cli.model.linear import stability
    from bounce_cli.analysis.sweep import evaluate_point

    tasks = sweep.point_tasks_of(config)
    costs = []
    for task in tasks:
        start = time.process_time()
        evaluate_point(task)
        costs.append(time.process_time() - start)
    start = time.perf_counter()
    with parallel.LocalPool(2) as pool:
        list(pool.map(stability, [config.params] * 2))  # each worker imports the engine
    pool_start = time.perf_counter() - start
    serial = sum(costs)
    print(f"per point: {min(costs):.3f} to {max(costs):.3f} s CPU, {serial:.2f} s in all; "
          f"pool start {pool_start:.2f} s")
    for jobs in job_counts:
        if jobs < 2:
            continue
        free = [pool_start] * jobs
        for cost in costs:  # in order, to the worker that is free first
            k = free.index(min(free))
            free[k] += cost
        print(f"--jobs {jobs} on an idle machine (estimate): {max(free):.2f} s, speed-up "
              f"{serial / max(free):.2f}x")


if __name__ == "__main__":
    main()
