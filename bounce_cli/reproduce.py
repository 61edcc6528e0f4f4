"""``bounce reproduce``: run every bundled config and write the gallery ``results/README.md``.

Orchestration only: each experiment runs through the same path as its own command.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from .experiments.base import Experiment

#: the bundled experiments, in the paper's order of figures
EXPERIMENT_NAMES = ("trajectory", "basin", "stability", "regression", "acf", "impulse")

#: caption of every figure: (file, paper figure and section, what it shows)
CAPTIONS: dict[str, list[tuple[str, str]]] = {
    "trajectory": [
        ("trajectory.png", "Figs. 2-3 (section 3): ball and racket trajectories of the two "
         "coexisting attractors, period-1 (v0 = 4.8 m/s) and sticking (v0 = 5.7 m/s), with "
         "the discrete v_k and theta_k per bounce."),
    ],
    "basin": [
        ("basin.png", "Fig. 4 (section 3): domain of attraction of the period-1 attractor; "
         "white period-1, grey sticking, black below the racket."),
        ("basin_iterations.png", "Section 3: number of impacts until each initial condition "
         "was classified."),
    ],
    "stability": [
        ("stability.png", "Fig. 5 (section 4): stability diagram in (alpha, AC) and the "
         "largest |lambda| where stable."),
    ],
    "regression": [
        ("regression.png", "Fig. 7 (section 5, eq. 15): trial means of racket amplitude "
         "regressed on the squared racket period (simulated trials)."),
    ],
    "acf": [
        ("acf.png", "Fig. 8 (section 6): auto- and cross-correlation functions of the "
         "stochastic map: theory (circles) and samples (crosses)."),
    ],
    "impulse": [
        ("impulse.png", "Fig. 9 (section 7): relaxation of velocity and phase after a "
         "perturbation of the coefficient of restitution (model curves)."),
        ("impulse_linear.png", "Fig. 10 (section 7): full map vs its linearisation with the "
         "same Jacobian."),
    ],
}


def load_experiment(name: str) -> Experiment:
    module = importlib.import_module(f".experiments.{name}", __package__)
    return module.EXPERIMENT


def gallery_markdown(results: Path, claims_table: str) -> str:
    """The text of ``results/README.md``: every figure with its caption, then the claims."""
    lines = [
        "# Reproduced figures",
        "",
        "Written by `bounce reproduce` from the bundled configs (`configs/`). Each folder holds",
        "the CSV data behind its figures and `run.json` (resolved config, versions, timing).",
        "",
    ]
    for name in EXPERIMENT_NAMES:
        lines += [f"## {name}", ""]
        for png, caption in CAPTIONS[name]:
            if (results / name / png).is_file():
                lines += [f"![{png}]({name}/{png})", "", f"*{caption}*", ""]
            else:
                lines += [f"*(missing: {name}/{png})*", ""]
    lines += ["## Claims of the paper", "", "From `bounce verify`:", "", claims_table, ""]
    return "\n".join(lines)
