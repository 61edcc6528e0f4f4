"""Times `bounce study` on a simulated study against a reference route, side by side.

    python benchmarks/study.py                       # 4 x 2 x 10 x 20 s, --jobs 1 and 2
    python benchmarks/study.py --reference a2f02a4 --jobs 2 --repeat 2
    python benchmarks/study.py --reference env       # this tree with BOUNCE_LAB=python

The study is made once by `bounce simulate-study` (subjects x 2 conditions x trials of 20 s,
``--subjects``, ``--trials``) in a temporary folder. The reference is a git revision checked
out with `git worktree` into a temporary folder and run from there (``PYTHONPATH``, the same
interpreter and packages), or ``env``: this tree with the simulated lab's Python loop
(``BOUNCE_LAB=python``). For each ``--jobs`` the reference and this tree run in turn
(A B A B ...: the machine's drift shows in both), each a whole process; wall time by the
clock, CPU time (user + sys of the process and its workers) by ``os.wait4``. The last run of
each writes its CSVs, and ``--compare`` then compares them (``compare_csvs.py``: identical
or within rtol 1e-9).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def route_env(tree: Path) -> dict[str, str]:
    """The environment of a route that runs the bounce_cli of ``tree``: ``python -m`` puts
    its working directory first on ``sys.path``, so a route runs in its own tree as well
    (``timed``'s ``cwd``) with the tree on ``PYTHONPATH`` (for its workers)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    env.pop("BOUNCE_LAB", None)
    return env


def check_route(tree: Path, env: dict[str, str]) -> None:
    """Fail unless ``python -m bounce_cli`` with ``env`` in ``tree`` imports ``tree``'s
    package (not an installed one, not the directory the benchmark was started in)."""
    found = subprocess.run([sys.executable, "-c", "import bounce_cli; print(bounce_cli.__file__)"],
                           env=env, cwd=tree, check=True, capture_output=True, text=True)
    path = Path(found.stdout.strip()).resolve()
    if Path(tree).resolve() not in path.parents:
        raise SystemExit(f"the route of {tree} imports bounce_cli from {path}")


def timed(command: list[str], env: dict[str, str], cwd: Path | None = None
          ) -> tuple[float, float, int]:
    """(wall s, CPU s of the process and its children, exit code) of one run in ``cwd``."""
    start = time.perf_counter()
    process = subprocess.Popen(command, env=env, cwd=cwd, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    err = process.stderr.read().decode() if process.stderr else ""
    if process.returncode not in (0, 1):
        sys.stderr.write(err)
    return wall, usage.ru_utime + usage.ru_stime, process.returncode


def make_study(folder: Path, subjects: int, trials: int) -> Path:
    subprocess.run([sys.executable, "-m", "bounce_cli", "simulate-study", "--out", str(folder),
                    "--set", f"subjects.count={subjects}", "--set", f"trials={trials}", "-q"],
                   check=True, cwd=ROOT)
    return folder / "study.csv"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", default="env",
                        help="a git revision, or env (BOUNCE_LAB=python on this tree)")
    parser.add_argument("--jobs", default="1,2", help="comma-separated --jobs values")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--subjects", type=int, default=4)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--manifest", type=Path, help="an existing study's manifest instead")
    parser.add_argument("--figures", default=None, help="--figures for this tree's runs")
    parser.add_argument("--no-warmup", dest="warmup", action="store_false",
                        help="no untimed run of each route on a 1 x 2 x 2 study first (it "
                             "compiles the routes' bytecode where PYTHONDONTWRITEBYTECODE "
                             "is unset)")
    parser.add_argument("--compare", action="store_true",
                        help="compare the two routes' CSVs (compare_csvs.py)")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bounce-study-bench-"))
    try:
        manifest = (args.manifest.resolve() if args.manifest  # (each route runs in its tree)
                    else make_study(work / "sim", args.subjects, args.trials))
        base_env = route_env(ROOT)
        if args.reference == "env":
            ref_tree, ref_env = ROOT, {**base_env, "BOUNCE_LAB": "python"}
            ref_label = "this tree, BOUNCE_LAB=python"
        else:
            ref_tree = work / "reference"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach",
                            str(ref_tree), args.reference], check=True, capture_output=True)
            ref_env = route_env(ref_tree)
            ref_label = f"revision {args.reference}"
        check_route(ROOT, base_env)
        check_route(ref_tree, ref_env)
        routes = {"reference": (ref_env, [], ref_tree),
                  "this tree": (base_env, [] if args.figures is None
                                else ["--figures", args.figures], ROOT)}
        if args.warmup:  # each route's bytecode compiled and its files cached, untimed
            small = make_study(work / "warmup", 1, 2)
            for name, (env, _extra, tree) in routes.items():
                timed([sys.executable, "-m", "bounce_cli", "study", "--manifest", str(small),
                       "--out", str(work / f"warmup-{name.replace(' ', '-')}"), "-q",
                       "--force"], env, tree)
        results: dict[tuple[str, int], list[tuple[float, float]]] = {}
        for jobs in [int(j) for j in args.jobs.split(",")]:
            for _ in range(args.repeat):
                for name, (env, extra, tree) in routes.items():
                    out = work / f"out-{name.replace(' ', '-')}-{jobs}"
                    command = [sys.executable, "-m", "bounce_cli", "study", "--manifest",
                               str(manifest), "--out", str(out), "--jobs", str(jobs), "-q",
                               "--force", *extra]
                    wall, cpu, code = timed(command, env, tree)
                    print(f"  {name:9s} --jobs {jobs}: {wall:7.1f} s wall, {cpu:7.1f} s CPU "
                          f"(exit {code})", flush=True)
                    results.setdefault((name, jobs), []).append((wall, cpu))
        print(f"\nreference: {ref_label}; study: {manifest}")
        print("| route | --jobs | wall (median) | CPU (median) | wall vs reference |")
        print("|---|---|---|---|---|")
        for (name, jobs), runs in results.items():
            wall = statistics.median(w for w, _ in runs)
            cpu = statistics.median(c for _, c in runs)
            ref = statistics.median(w for w, _ in results[("reference", jobs)])
            print(f"| {name} | {jobs} | {wall:.1f} s | {cpu:.1f} s | {ref / wall:.2f}x |")
        if args.compare:
            for jobs in sorted({j for _, j in results}):
                subprocess.run([sys.executable, str(ROOT / "benchmarks" / "compare_csvs.py"),
                                str(work / f"out-reference-{jobs}"),
                                str(work / f"out-this-tree-{jobs}")])
    finally:
        if args.reference != "env":
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(work / "reference")], capture_output=True)
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
