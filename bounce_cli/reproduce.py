"""``bounce reproduce``: run every bundled config and write the gallery ``results/README.md``.

Orchestration only: each experiment runs through the same path as its own command; which
experiments and which captions come from :mod:`bounce_cli.registry`.
"""

from __future__ import annotations

from pathlib import Path

from .registry import reproduced


def gallery_markdown(results: Path, claims_table: str) -> str:
    """The text of ``results/README.md``: every figure with its caption, then the claims."""
    lines = [
        "# Reproduced figures",
        "",
        "Written by `bounce reproduce` from the bundled configs (`configs/`). Each folder holds",
        "the CSV data behind its figures and `run.json` (resolved config, seed, versions; the",
        "start time, wall time and git commit of a run are in `timing.json`, not committed).",
        "",
    ]
    for entry in reproduced():
        name = entry.name
        lines += [f"## {name}", ""]
        for png, caption in entry.figures:
            if (results / name / png).is_file():
                lines += [f"![{png}]({name}/{png})", "", f"*{caption}*", ""]
            else:
                lines += [f"*(missing: {name}/{png})*", ""]
    lines += ["## Claims of the paper", "", "From `bounce verify`:", "", claims_table, ""]
    return "\n".join(lines)
