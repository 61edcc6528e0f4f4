"""Times `bounce reproduce` (results present) one experiment at a time against side by side,
in the same run.

    python benchmarks/reproduce.py                           # --jobs 1 vs --jobs 2, 3 rounds
    python benchmarks/reproduce.py --reference 688ff64 --repeat 5

Each route reruns every bundled experiment into its own copy of the committed `results/`
(the run leaves tables that agree within the reproduction tolerance as they are, as on a
clean checkout). The routes: this tree with `--jobs 1` (the experiments one after another,
as `bounce reproduce` ran them until 2026-12-07) and with `--jobs 2` (two forked lanes,
``runtime.forked.ForkedLanes``), and with ``--reference`` a git revision checked out with
`git worktree` and run as it was (its default jobs). They run in turn (A B C A B C ...),
each a whole process; wall time by the clock, CPU time (the process and its lanes) by
``os.wait4``; per route the median and each round's wall time are printed, and each
round's ratio of the one-at-a-time route to the side-by-side one.
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", default=None,
                        help="also time this git revision's `bounce reproduce`")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bounce-reproduce-bench-"))
    tree = work / "reference"
    here = study_bench.route_env(ROOT)
    routes: dict[str, tuple[dict[str, str], Path, list[str]]] = {
        "one at a time (--jobs 1)": (here, ROOT, ["--jobs", "1"]),
        "side by side (--jobs 2)": (here, ROOT, ["--jobs", "2"]),
    }
    try:
        if args.reference:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                            args.reference], check=True, capture_output=True)
            env = study_bench.route_env(tree)
            study_bench.check_route(tree, env)
            routes[f"reference {args.reference}"] = (env, tree, [])
        study_bench.check_route(ROOT, here)
        results: dict[str, list[tuple[float, float]]] = {name: [] for name in routes}
        for index in range(len(routes)):
            shutil.copytree(ROOT / "results", work / f"results-{index}")
        for round_ in range(args.repeat):
            for index, (name, (env, route_tree, extra)) in enumerate(routes.items()):
                command = [sys.executable, "-m", "bounce_cli", "reproduce", "-q",
                           "--out", str(work / f"results-{index}"), *extra]
                wall, cpu, code = study_bench.timed(command, env, route_tree)
                print(f"  round {round_ + 1} {name:26s}: {wall:6.2f} s wall, {cpu:6.2f} s CPU "
                      f"(exit {code})", flush=True)
                results[name].append((wall, cpu))
        print("\n| route | wall (median) | CPU (median) | each round's wall |")
        print("|---|---|---|---|")
        for name, runs in results.items():
            wall = statistics.median(w for w, _ in runs)
            cpu = statistics.median(c for _, c in runs)
            rounds = ", ".join(f"{w:.1f}" for w, _ in runs)
            print(f"| {name} | {wall:.2f} s | {cpu:.2f} s | {rounds} s |")
        one, two = (results[name] for name in list(routes)[:2])
        ratios = sorted(a / b for (a, _), (b, _) in zip(one, two))
        print(f"\none at a time / side by side, each round: "
              f"{', '.join(f'{r:.2f}x' for r in ratios)} (median {statistics.median(ratios):.2f}x)")
    finally:
        if args.reference:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(tree)], capture_output=True)
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
