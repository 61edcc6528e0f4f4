"""Coverage and bias of the VARX model-bias intervals over simulated units, by route.

``acf --data``'s VARX estimates are corrected by the model's bias for them, which the model's
own simulated sessions measure (``experiments.data_side.varx_prediction``); the corrected
estimate's interval comes from those sessions' order statistics. A change in how the sessions
are drawn (issue 35: racket cycles counted without hinging on an ulp, the sessions simulated
at once) changes the draws, not the distribution: this script shows it on units with a known
truth. The units are made once (``make``: exact impacts of the simulated lab with a racket
jittered per cycle, written to an .npz), and each route (a tree of bounce, on PYTHONPATH)
evaluates the same units (``evaluate``): per estimator and quantity, the coverage of the 95 %
interval of ``<estimator>+model_bias`` for eq. 9's J and eq. 10's radius, and the mean and
median bias of the corrected estimate::

    python benchmarks/varx_coverage.py make --units 200 --out /tmp/units.npz
    python benchmarks/varx_coverage.py evaluate /tmp/units.npz            # this tree
    PYTHONPATH=<other tree> python benchmarks/varx_coverage.py evaluate /tmp/units.npz

``both`` does the three steps with a git revision as the other route (a worktree)::

    python benchmarks/varx_coverage.py both --reference bba8238 --units 200
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: the unit's model (a racket of the paper's impulse experiment, alpha 0.5: radius 0.5) and
#: its jitter: 10 ms and 3 mm per cycle, q_v 0.04 m/s; 10 trials of 40 impacts
PARAMS = dict(alpha=0.5, g=9.81, racket_amplitude=0.3, racket_period=0.92)
SESSION = (0.01, 0.003, 0.04)
LENGTHS = [40] * 10


def make(units: int, out: Path, seed: int) -> None:
    from bounce_cli.data.simulated_runs import RacketSession, simulate_runs
    from bounce_cli.experiments.data_side import simulated_trials
    from bounce_cli.model.params import ModelParams

    params = ModelParams(**PARAMS)
    arrays = {}
    for u, unit_seed in enumerate(np.random.SeedSequence(seed).spawn(units)):
        runs, _ = simulate_runs(params, RacketSession(*SESSION), LENGTHS, unit_seed)
        trials, racket = simulated_trials(runs)
        arrays[f"y{u}"] = np.stack(trials)
        arrays[f"u{u}"] = np.stack(racket)
    np.savez(out, **arrays)
    print(f"{units} units of {len(LENGTHS)} x {LENGTHS[0]} impacts -> {out}")


def evaluate(path: Path) -> dict:
    import bounce_cli
    from bounce_cli.analysis.var_fit import fit_var1
    from bounce_cli.experiments.data_side import (
        AcfDataBlock,
        plausible_fit,
        prediction_rows,
        varx_prediction,
    )
    from bounce_cli.model.linear import jacobian, stability
    from bounce_cli.model.params import ModelError, ModelParams

    params = ModelParams(**PARAMS)
    truth = dict(zip(("J_vv", "J_vtheta", "J_thetav", "J_thetatheta"),
                     jacobian(params).ravel()), spectral_radius=stability(params).spectral_radius)
    data = np.load(path)
    units = len([k for k in data.files if k.startswith("y")])
    inside: dict[tuple[str, str], list[bool]] = {}
    error: dict[tuple[str, str], list[float]] = {}
    started = time.perf_counter()
    for u in range(units):
        trials, racket = list(data[f"y{u}"]), list(data[f"u{u}"])
        fits = {}
        for method in ("ols", "lag2"):
            try:
                fits[f"varx_{method}"] = plausible_fit(fit_var1(trials, method, jackknife=True,
                                                                exog=racket))
            except ModelError as exc:
                fits[f"varx_{method}"] = exc
        sd = np.sqrt(np.mean(np.concatenate([r - r.mean(axis=0) for r in racket]) ** 2, axis=0))
        block = AcfDataBlock(trust_seed=u)
        prediction = varx_prediction(params, fits, trials, sd, block)
        if prediction is None:
            continue
        rows, _ = prediction_rows(prediction, fits, params, 0.95)
        for row in rows:
            if not row["source"].endswith("+model_bias") or row["quantity"] not in truth:
                continue
            key = (row["source"], row["quantity"])
            value = truth[row["quantity"]]
            inside.setdefault(key, []).append(row["ci_low"] <= value <= row["ci_high"])
            error.setdefault(key, []).append(row["estimate"] - value)
    table = {f"{source} {quantity}": {
        "units": len(hits), "coverage": float(np.mean(hits)),
        "mean_bias": float(np.mean(error[(source, quantity)])),
        "median_bias": float(np.median(error[(source, quantity)])),
        "sd": float(np.std(error[(source, quantity)], ddof=1))}
        for (source, quantity), hits in inside.items()}
    return {"bounce": str(Path(bounce_cli.__file__).parent.parent), "units": units,
            "seconds": round(time.perf_counter() - started, 1), "rows": table}


def both(reference: str, units: int, seed: int) -> None:
    work = Path(tempfile.mkdtemp(prefix="bounce-varx-coverage-"))
    tree = work / "reference"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                    reference], check=True, capture_output=True)
    try:
        data = work / "units.npz"
        make(units, data, seed)
        results = {}
        for name, path in (("reference", tree), ("this tree", ROOT)):
            env = {**os.environ, "PYTHONPATH": str(path)}
            found = subprocess.run([sys.executable, str(Path(__file__).resolve()), "evaluate",
                                    str(data), "--json"], env=env, cwd=path, check=True,
                                   capture_output=True, text=True)
            results[name] = json.loads(found.stdout)
            if Path(results[name]["bounce"]).resolve() != path.resolve():
                raise SystemExit(f"the {name} route imported {results[name]['bounce']}")
        print(f"\n{units} units, reference {reference} "
              f"({results['reference']['seconds']} s) vs this tree "
              f"({results['this tree']['seconds']} s)\n")
        print("| estimate | quantity | coverage (reference) | coverage (this tree) | "
              "mean bias (reference) | mean bias (this tree) |")
        print("|---|---|---|---|---|---|")
        for key, row in results["this tree"]["rows"].items():
            old = results["reference"]["rows"].get(key, {})
            source, quantity = key.split(" ")
            print(f"| {source} | {quantity} | {old.get('coverage', float('nan')):.1%} | "
                  f"{row['coverage']:.1%} | {old.get('mean_bias', float('nan')):+.4f} | "
                  f"{row['mean_bias']:+.4f} |")
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                       capture_output=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    p = sub.add_parser("make")
    p.add_argument("--units", type=int, default=200)
    p.add_argument("--seed", type=int, default=35)
    p.add_argument("--out", type=Path, required=True)
    p = sub.add_parser("evaluate")
    p.add_argument("data", type=Path)
    p.add_argument("--json", action="store_true")
    p = sub.add_parser("both")
    p.add_argument("--reference", required=True)
    p.add_argument("--units", type=int, default=200)
    p.add_argument("--seed", type=int, default=35)
    args = parser.parse_args()
    if args.step == "make":
        make(args.units, args.out, args.seed)
    elif args.step == "evaluate":
        result = evaluate(args.data)
        if args.json:
            print(json.dumps(result))
        else:
            print(json.dumps(result, indent=2))
    else:
        both(args.reference, args.units, args.seed)


if __name__ == "__main__":
    main()
