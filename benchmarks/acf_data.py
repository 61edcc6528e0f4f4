"""Times `bounce acf --data` on 3 trials x 40 s (the paper's section 6 size) against a
reference route, side by side.

    python benchmarks/acf_data.py                          # against HEAD, 5 runs each
    python benchmarks/acf_data.py --reference bba8238 --repeat 7 --compare

The impacts are made once: `bounce simulate-recording` (3 trials of 40 s) and `bounce
extract` in a temporary folder. The reference is a git revision checked out with `git
worktree` and run from there (``PYTHONPATH``, the same interpreter and packages), as in
``study.py``. The routes run in turn (A B A B ...), each a whole process; wall time by the
clock, CPU time by ``os.wait4``; the medians are printed. ``--compare`` compares the last
runs' CSVs (``compare_csvs.py``).
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("study_bench", ROOT / "benchmarks" / "study.py")
assert _spec is not None and _spec.loader is not None
study_bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(study_bench)


def make_impacts(folder: Path, trials: int, duration_s: float) -> Path:
    bounce = [sys.executable, "-m", "bounce_cli"]
    subprocess.run([*bounce, "simulate-recording", "--out", str(folder / "rec"), "-q",
                    "--set", f"trials={trials}", "--set", f"duration_s={duration_s}"],
                   check=True, cwd=ROOT)
    subprocess.run([*bounce, "extract", "--data", str(folder / "rec" / "recording.csv"),
                    "--out", str(folder / "ext"), "-q"], check=True, cwd=ROOT)
    return folder / "ext" / "impacts.csv"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", default="HEAD", help="a git revision")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--duration", type=float, default=40.0, help="s per trial")
    parser.add_argument("--compare", action="store_true",
                        help="compare the two routes' CSVs (compare_csvs.py)")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bounce-acf-bench-"))
    tree = work / "reference"
    try:
        impacts = make_impacts(work, args.trials, args.duration)
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                        args.reference], check=True, capture_output=True)
        routes = {"reference": (study_bench.route_env(tree), tree),
                  "this tree": (study_bench.route_env(ROOT), ROOT)}
        for env, route_tree in routes.values():
            study_bench.check_route(route_tree, env)
        results: dict[str, list[tuple[float, float]]] = {name: [] for name in routes}
        for _ in range(args.repeat):
            for name, (env, route_tree) in routes.items():
                out = work / f"out-{name.replace(' ', '-')}"
                command = [sys.executable, "-m", "bounce_cli", "acf", "--data", str(impacts),
                           "--out", str(out), "-q", "--force"]
                wall, cpu, code = study_bench.timed(command, env, route_tree)
                print(f"  {name:9s}: {wall:6.2f} s wall, {cpu:6.2f} s CPU (exit {code})",
                      flush=True)
                results[name].append((wall, cpu))
        print(f"\nreference: revision {args.reference}; impacts: {impacts} "
              f"({args.trials} trials x {args.duration:g} s)")
        print("| route | wall (median) | CPU (median) | wall vs reference |")
        print("|---|---|---|---|")
        ref = statistics.median(w for w, _ in results["reference"])
        for name, runs in results.items():
            wall = statistics.median(w for w, _ in runs)
            cpu = statistics.median(c for _, c in runs)
            print(f"| {name} | {wall:.2f} s | {cpu:.2f} s | {ref / wall:.2f}x |")
        if args.compare:
            subprocess.run([sys.executable, str(ROOT / "benchmarks" / "compare_csvs.py"),
                            str(work / "out-reference"), str(work / "out-this-tree")])
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                       capture_output=True)
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
