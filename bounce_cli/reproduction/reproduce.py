"""``bounce reproduce``: run every bundled config and write the gallery ``results/README.md``.

Orchestration only: each experiment runs through the same path as its own command; which
experiments and which captions come from :mod:`bounce_cli.experiments.registry`.

The reproduction tolerance (one rule, used by ``bounce reproduce`` and by the regression test
of the committed results): floats agree to rtol 1e-6 / atol 1e-9 (the runs are deterministic:
seeded streams, no dependence on the number of workers; the slack absorbs what differs
between CPUs, BLAS kernels and libm builds: seen up to 2e-7 relative); categorical columns
must match exactly, except the basin's outcome, where at most 1 point in 10^4 may flip (a
grid point lying on a basin boundary to within rounding); a few columns whose last digits are
rounding by construction are compared to their stated precision (``ATOL_FOR``). The tables
filled by orbits on chaotic attractors (``bounce bifurcation``, ``continuation``'s
brute-force diagram, ``sweep``) are compared by what reproduces of such orbits, each at the
precision it has (``chaotic_tables``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..experiments.registry import reproduced
from ..runtime.artifacts import RunTables
from .chaotic_tables import RULES

RTOL, ATOL = 1e-6, 1e-9
#: (experiment, table, column) -> fraction of values that may differ
MAX_FLIPPED_FRACTION = {("basin", "basin.csv", "outcome"): 1e-4,
                        ("basin", "basin.csv", "iterations"): 1e-4}
#: bounce control's "fastest" gains minimise the spectral radius where the three eigenvalues
#: nearly coincide (0.14527 and 0.14527 +- 2e-6 i): a cluster of three moves by about
#: eps^(1/3) |lambda| ~ 6e-6 * 0.145 ~ 1e-6 when the matrix moves by one rounding eps, so the
#: last bits of the optimiser's gains (numpy/libm versions) split it differently (seen:
#: imaginary parts 2.20e-6 vs 2.22e-6); the spectral radius itself keeps rtol 1e-6
EIGEN_COLUMNS = [f"lambda{i}_{part}" for i in (1, 2, 3) for part in ("re", "im")]
#: stability's crosscheck estimates eq. 10's radius two ways whose last digits are rounding
#: (``model.linear``): the contraction fit follows a deviation from the fixed point down to the
#: rounding floor (1e-13), where the deviation is rounding itself (the orbit settles on the
#: computed fixed point, not on eq. 7's), so the impact at which it first drops below the
#: floor, and with it the fitted rate, moves with the last bits of libm and of the code paths;
#: the finite-difference Jacobian (relative step 1e-6) carries rounding of eps / 1e-6 into
#: ``rel_diff_fd`` (about 1e-9). Measured by moving the racket amplitude or g by a few ulps:
#: up to 5 impacts, 4.3e-4 in the rate, 6e-9 in rel_diff_fd (seen between this machine and an
#: emulated Nehalem: 318 vs 319 impacts, rate 0.934882 vs 0.934924). Compared to those
#: precisions; eq. 10's radius and the Jacobian's keep the full tolerance.
CROSSCHECK_ESTIMATES = {"radius_empirical": 1e-3, "rel_diff_empirical": 1e-3,
                        "impacts_fitted": 10, "rel_diff_fd": 1e-7}
ATOL_FOR = {("control", "eigen.csv", column): 1e-6 for column in EIGEN_COLUMNS} | {
    ("stability", "crosscheck.csv", column): atol
    for column, atol in CROSSCHECK_ESTIMATES.items()}


#: tables whose rows are where an adaptive step control put them: one last bit more or less
#: in a Newton corrector's convergence adds or drops a step (seen: 786 rows instead of 780
#: under another BLAS kernel), so they are compared by what they trace, the identity of each
#: branch (these columns); the located values (bifurcations.csv, feigenbaum.csv) keep the
#: full tolerance
ADAPTIVE_TABLES = {("continuation", "branches.csv"): ["branch", "start", "parent_branch",
                                                       "period", "cycles"],
                   ("continuation", "orbits.csv"): ["branch"]}


def table_drift(experiment: str, table: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                tables: RunTables | None = None) -> list[str]:
    """Where a regenerated table lies outside the reproduction tolerance of the committed one.

    Parameters
    ----------
    experiment, table
        The experiment's name and the table's file name (they select the per-column
        exceptions ``MAX_FLIPPED_FRACTION`` and ``ATOL_FOR``, ``ADAPTIVE_TABLES``, and the
        rules of the tables filled by chaotic orbits, ``chaotic_tables.RULES``).
    fresh, committed
        The two tables as read back from their files (the same reader for both).
    tables
        Both runs' tables and config, which the rules of ``chaotic_tables`` read (an orbit's
        points are compared as its ``attractors.csv`` row says); without them every table is
        compared value by value.

    Returns
    -------
    list of str
        One line per disagreement (columns, length, or a column's values); empty when the
        tables agree within the tolerance.
    """
    where = f"{experiment}/{table}"
    if list(fresh.columns) != list(committed.columns):
        return [f"{where}: columns {list(fresh.columns)} instead of {list(committed.columns)}"]
    rule = RULES.get((experiment, table))
    if rule is not None and tables is not None:
        def deterministic(a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
            return value_drift(experiment, table, a, b)

        return rule(where, fresh, committed, tables, deterministic, RTOL, ATOL)
    return value_drift(experiment, table, fresh, committed)


def value_drift(experiment: str, table: str, fresh: pd.DataFrame,
                committed: pd.DataFrame) -> list[str]:
    """``table_drift``'s rule for a table whose values reproduce one by one: floats to
    RTOL/ATOL (or ``ATOL_FOR``), the rest exactly (but for ``MAX_FLIPPED_FRACTION``), an
    adaptive table by its identity columns."""
    where = f"{experiment}/{table}"
    identity = ADAPTIVE_TABLES.get((experiment, table))
    if identity is not None:
        fresh, committed = (frame[identity].drop_duplicates().reset_index(drop=True)
                            for frame in (fresh, committed))
    if len(fresh) != len(committed):
        return [f"{where}: {len(fresh)} rows instead of {len(committed)}"]
    problems = []
    for column in committed.columns:
        a, b = fresh[column], committed[column]
        allowed = MAX_FLIPPED_FRACTION.get((experiment, table, column), 0.0)
        if (pd.api.types.is_numeric_dtype(b) and pd.api.types.is_numeric_dtype(a)
                and not pd.api.types.is_bool_dtype(b)):
            close = np.isclose(a.to_numpy(float), b.to_numpy(float), rtol=RTOL,
                               atol=ATOL_FOR.get((experiment, table, column), ATOL),
                               equal_nan=True)
        else:
            text = [col.astype(object).where(col.notna(), "<missing>").astype(str)
                    for col in (a, b)]
            close = (text[0] == text[1]).to_numpy(bool)
        if close.size and 1.0 - close.mean() > allowed:
            problems.append(
                f"{where} column {column}: {np.sum(~close)} of {len(close)} values drifted "
                f"from the committed baseline; first at row {np.flatnonzero(~close)[:5]}")
    return problems


def tables_agree(experiment: str):
    """``RunDirectory.commit``'s ``agrees`` for one experiment: (table, new, previous, both
    runs' tables) -> whether the new table agrees with the previous within the reproduction
    tolerance."""
    def agrees(table: str, new: pd.DataFrame, previous: pd.DataFrame,
               tables: RunTables) -> bool:
        return not table_drift(experiment, table, new, previous, tables)
    return agrees


def experiment_status(comparison: dict[str, str]) -> str:
    """One line per experiment for ``bounce reproduce``: ``identical``, ``within tolerance``
    (and which tables), ``changed`` (and which files; the tables within tolerance that were
    rewritten with them; the files that were not there before) or ``new`` (every file: a
    folder without earlier results), from ``RunDirectory.comparison``."""
    changed = sorted(name for name, how in comparison.items() if how == "changed")
    new = sorted(name for name, how in comparison.items() if how == "new")
    if new and len(new) == len(comparison):
        return "new (no earlier results there): " + ", ".join(new)
    parts = [f"{word}: {', '.join(names)}" for word, names in (("changed", changed),
                                                               ("new", new)) if names]
    if parts:
        along = sorted(name for name, how in comparison.items() if how == "rewritten")
        return "; ".join(parts) + (
            f" (rewritten with them, within tolerance: {', '.join(along)})" if along else "")
    close = sorted(name for name, how in comparison.items() if how == "within tolerance")
    if close:
        return "within tolerance (left as committed): " + ", ".join(close)
    return "identical"


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
