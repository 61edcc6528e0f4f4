"""What of a chaotic orbit reproduces on another machine: the reproduction rules of the tables
that ``bounce bifurcation``, ``bounce continuation`` and ``bounce sweep`` fill by iterating
the map (eqs. 5, 6) for hundreds of impacts.

A last-bit difference (another libm's sin or cos, another CPU's code path: seen between glibc's
FMA and non-FMA ``sin``) grows by the Lyapunov exponent at every impact of a chaotic orbit and
is of the order of the state after 100-200 impacts. From there on two machines follow two
different orbits of the same attractor: its recorded points, the impact at which a chaotic
transient ends in sticking, and whether it ends before the measurement does are not
reproducible digit for digit, on any two machines. What reproduces is what the attractor and
the statistics of its orbits fix; these rules compare that, each at the precision it has:

* **Late outcomes** (``late_outcome``): an orbit on a chaotic attractor (``chaotic``, or
  ``unresolved``: not settled) or one that stuck only at impact ``LATE_IMPACT`` or later (a
  chaotic transient or a chatter decided at the 1 ms rule's edge). Between two late outcomes
  the label, period and sticking impact may differ (chaotic <-> sticking at impact 54 ... 1773
  was seen when g moved by 1-3 ulps); every other row's outcome must be the same.
* **Lyapunov exponents**: each is a finite-time mean with a standard error (batch means,
  ``analysis.bifurcation.lyapunov_standard_error``); two agree within ``Z_EXPONENT`` combined
  standard errors (or the reproduction tolerance, when that is larger).
* **Points of an orbit**: a periodic orbit's cycle is the same to the full tolerance, starting
  at any of its impacts (a chaotic transient can end at another phase of the cycle); the
  points of an aperiodic orbit are two samples of one attractor, compared by the
  two-sample Kolmogorov-Smirnov test of the velocities and of the phases (the circle cut at
  the widest gap of the two samples together, so that a band across 0/360 deg is not cut),
  rejected below ``P_MIN``.
* **Basin fractions over a parameter grid** (``bounce sweep``): an orbit still chaotic when
  the classification stops (undecided) or stuck just before is decided by its last bits, so
  per parameter point up to ``allowed_flips`` points may change class (binomial noise of the
  undecided points, 4 standard deviations); the basin entropies within the change so many
  flips can make (each flip moves one box's entropy by at most 2 ln(m)/m for m cells a box).

Measured (``python -m bounce_cli`` runs at g moved by -3..3 ulps, and the whole of ``bounce
reproduce`` with glibc's non-FMA libm: ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``): no
sticking impact below 36 changed; exponents moved by at most 3.6 combined standard errors
(830 pairs); the largest Kolmogorov-Smirnov statistic of 1508 pairs of chaotic orbits was
0.28 (p = 0.012); a sweep point changed at most 47 of its 1600 points (993 undecided).
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np
import pandas as pd
from scipy.stats import ks_2samp

from ..analysis.bifurcation import detect_period
from ..model.params import phase_difference
from ..runtime.artifacts import RunTables

#: a stick at this impact or later is a late outcome (see the module doc: measured from 36 on)
LATE_IMPACT = 30
#: outcomes of an orbit still moving on a chaotic attractor (or not settled) when it ends
MOVING = ("chaotic", "unresolved")
STUCK = ("sticking", "resting")
#: exponents agree within this many combined standard errors (the errors come from 10 batches:
#: a t distribution with about 18 degrees of freedom, P(|t| > 6) ~ 1e-5 per row)
Z_EXPONENT = 6.0
#: two samples of one attractor's points are told apart below this p-value
P_MIN = 1e-6
#: the period tolerance (m/s and rad) with which the points of an orbit are read as periodic:
#: the experiments' own (``period_tolerance``)
PERIOD_TOLERANCE = 1e-6


#: a rule: (where, fresh, committed, both runs, the deterministic rule for some columns)
#: -> one line per disagreement
Deterministic = Callable[[pd.DataFrame, pd.DataFrame], list[str]]


def late_outcome(attractors: pd.DataFrame) -> np.ndarray:
    """Per row of an ``attractors.csv``: whether its outcome is late (see the module doc)."""
    name = attractors["attractor"].astype(str)
    stuck_late = name.isin(STUCK) & (attractors["stuck_at_impact"] >= LATE_IMPACT)
    return (name.isin(MOVING) | stuck_late).to_numpy()


def _keys(frame: pd.DataFrame) -> list[str]:
    """The columns that name an orbit: the swept parameter (first column) and its start."""
    return [frame.columns[0], "initial_condition"]


def exponents_agree(a, b, se_a, se_b, rtol: float, atol: float) -> np.ndarray:
    """Finite-time exponents agree within Z_EXPONENT combined standard errors or the
    reproduction tolerance; NaN (no exponent) and -inf (superstable) only with themselves."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    spread = Z_EXPONENT * np.hypot(np.nan_to_num(se_a), np.nan_to_num(se_b))
    with np.errstate(invalid="ignore"):
        close = np.abs(a - b) <= np.maximum(spread, atol + rtol * np.abs(b))
    return close | (a == b) | (np.isnan(a) & np.isnan(b))


def _problem(where: str, column: str, bad: np.ndarray, what: str = "") -> list[str]:
    if not bad.any():
        return []
    return [f"{where} column {column}: {int(bad.sum())} of {bad.size} values drifted from the "
            f"committed baseline{what}; first at row {np.flatnonzero(bad)[:5]}"]


def attractors_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                     tables: RunTables, deterministic: Deterministic, rtol: float,
                     atol: float) -> list[str]:
    """``attractors.csv`` of ``bounce bifurcation``: one row per orbit (value x start)."""
    outcome = ["attractor", "period", "stuck_at_impact"]
    statistical = outcome + ["lyapunov_per_impact", "lyapunov_se_per_impact"]
    fixed = [c for c in committed.columns if c not in statistical]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    late = late_outcome(fresh) & late_outcome(committed)
    for column in outcome:
        same = (fresh[column].astype(str) == committed[column].astype(str)).to_numpy()
        problems += _problem(where, column, ~(same | late), " (not a late outcome)")
    exponent = exponents_agree(fresh.lyapunov_per_impact, committed.lyapunov_per_impact,
                               fresh.lyapunov_se_per_impact,
                               committed.lyapunov_se_per_impact, rtol, atol)
    moved = (fresh.attractor.astype(str) != committed.attractor.astype(str)).to_numpy() & late
    problems += _problem(where, "lyapunov_per_impact", ~(exponent | moved),
                         f" by more than {Z_EXPONENT:g} standard errors")
    # the errors themselves are statistics of a statistic (an intermittent orbit's moved by a
    # factor 3.5, a periodic orbit's from 3e-5 to 2e-11 where a transient ended while
    # measured in one run only): only where they exist is compared
    has_se = [np.isfinite(t.lyapunov_se_per_impact.to_numpy(float)) for t in (fresh, committed)]
    problems += _problem(where, "lyapunov_se_per_impact", (has_se[0] != has_se[1]) & ~moved,
                         " (missing in one run)")
    return problems


def _period_of(points: pd.DataFrame) -> int:
    """The smallest period of an orbit's recorded points (0: none), as the experiments read it."""
    v = points["v_m_s"].to_numpy(float)[None, :]
    theta = np.radians(points["theta_deg"].to_numpy(float))[None, :]
    return int(detect_period(v, theta, v.shape[1] // 2, PERIOD_TOLERANCE)[0])


def cycles_agree(a: pd.DataFrame, b: pd.DataFrame, period: int, rtol: float,
                 atol: float) -> bool:
    """Whether two period-``period`` orbits' recorded points are the same cycle to the
    reproduction tolerance, whichever impact of the cycle each recording starts at."""
    va, vb = a["v_m_s"].to_numpy(float)[:period], b["v_m_s"].to_numpy(float)
    ta = np.radians(a["theta_deg"].to_numpy(float))[:period]
    tb = np.radians(b["theta_deg"].to_numpy(float))
    if vb.size < period:
        return False
    for shift in range(period):
        vs, ts = np.roll(vb[:period], -shift), np.roll(tb[:period], -shift)
        if (np.allclose(vs, va, rtol=rtol, atol=atol)
                and np.all(np.abs(phase_difference(ts, ta)) <= atol + rtol * TWO_PI)):
            return True
    return False


TWO_PI = 2.0 * math.pi


def widest_gap_cut(theta_deg: np.ndarray) -> float:
    """The phase (deg) in the middle of the widest arc that no point of ``theta_deg`` falls
    on: cutting the circle there keeps a band of phases across 0/360 deg in one piece."""
    ordered = np.sort(np.mod(theta_deg, 360.0))
    gaps = np.diff(np.concatenate([ordered, [ordered[0] + 360.0]]))
    widest = int(np.argmax(gaps))
    return float(np.mod(ordered[widest] + gaps[widest] / 2.0, 360.0))


def samples_agree(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    """Whether two aperiodic orbits' recorded points can be samples of one attractor: the
    two-sample Kolmogorov-Smirnov test of the velocities and of the phases (the circle cut at
    the widest gap of both samples together) keeps p >= P_MIN."""
    if ks_2samp(a["v_m_s"], b["v_m_s"]).pvalue < P_MIN:
        return False
    both = np.concatenate([a["theta_deg"].to_numpy(float), b["theta_deg"].to_numpy(float)])
    cut = widest_gap_cut(both)
    ta, tb = (np.mod(t["theta_deg"].to_numpy(float) - cut, 360.0) for t in (a, b))
    return bool(ks_2samp(ta, tb).pvalue >= P_MIN)


def orbit_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                       period_fresh: Mapping[tuple, int], period_committed: Mapping[tuple, int],
                       may_be_missing: Callable[[tuple], bool], rtol: float,
                       atol: float) -> list[str]:
    """Recorded points of many orbits, compared orbit by orbit: each orbit's period on each
    side (``period_*``: key -> period, 0 when aperiodic); an orbit recorded on one side only
    is allowed where ``may_be_missing(key)`` (it stuck late on the other)."""
    keys = _keys(committed)
    groups_f = dict(tuple(fresh.groupby(keys, sort=False)))
    groups_c = dict(tuple(committed.groupby(keys, sort=False)))
    missing = [k for k in set(groups_f) ^ set(groups_c) if not may_be_missing(k)]
    problems = []
    if missing:
        problems.append(f"{where}: {len(missing)} orbit(s) recorded in one run only, not after a "
                        f"late outcome; first {sorted(missing)[:3]}")
    differ = []
    for key in sorted(set(groups_f) & set(groups_c)):
        a, b = groups_f[key], groups_c[key]
        pa, pb = period_fresh[key], period_committed[key]
        if pa and pb:
            ok = pa == pb and len(a) == len(b) and cycles_agree(a, b, pa, rtol, atol)
        else:
            ok = len(a) == len(b) and samples_agree(a, b)
        if not ok:
            differ.append(key)
    if differ:
        problems.append(f"{where}: {len(differ)} orbit(s) drifted from the committed baseline "
                        f"(another cycle, or points that cannot be samples of one attractor); "
                        f"first {differ[:3]}")
    return problems


def bifurcation_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                             tables: RunTables, deterministic: Deterministic, rtol: float,
                             atol: float) -> list[str]:
    """``bifurcation.csv``: each orbit's recorded points, read as its ``attractors.csv`` row
    says (periodic: the cycle; chaotic or unresolved: a sample of the attractor)."""
    rows = [tables.fresh["attractors.csv"], tables.committed["attractors.csv"]]
    keys = _keys(rows[1])
    periods = [dict(zip(zip(*(t[k] for k in keys)), t["period"].astype(int))) for t in rows]
    late = dict(zip(zip(*(rows[1][k] for k in keys)),
                    late_outcome(rows[0]) & late_outcome(rows[1])))
    return orbit_points_drift(where, fresh, committed, periods[0], periods[1],
                              lambda key: bool(late.get(key, False)), rtol, atol)


def diagram_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                         tables: RunTables, deterministic: Deterministic, rtol: float,
                         atol: float) -> list[str]:
    """``diagram.csv`` of ``bounce continuation``: each orbit's period read from its points;
    an aperiodic orbit may be missing on one side (it stuck there)."""
    keys = _keys(committed)
    periods = [{key: _period_of(group) for key, group in t.groupby(keys, sort=False)}
               for t in (fresh, committed)]
    aperiodic = {key for side in periods for key, p in side.items() if p == 0}
    return orbit_points_drift(where, fresh, committed, periods[0], periods[1],
                              lambda key: key in aperiodic, rtol, atol)


def values_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame, tables: RunTables,
                 deterministic: Deterministic, rtol: float, atol: float) -> list[str]:
    """``values.csv`` of ``bounce bifurcation``: one row per value, summarising its orbits
    (``attractors.csv``). At a value where some orbit's late outcome changed, the outcome
    columns may differ; the exponents (a maximum and a mean of the orbits' exponents) agree
    within Z_EXPONENT times the largest combined standard error of that value's orbits."""
    outcome = ["attractors", "dominant_attractor", "n_sticking"]
    exponents = ["lyapunov_max_per_impact", "lyapunov_dominant_per_impact"]
    fixed = [c for c in committed.columns if c not in outcome + exponents]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    rows = [tables.fresh["attractors.csv"], tables.committed["attractors.csv"]]
    column = committed.columns[0]
    changed = (rows[0].attractor.astype(str) != rows[1].attractor.astype(str)).to_numpy()
    value_changed = pd.Series(changed).groupby(rows[1][column].to_numpy()).any()
    se = np.hypot(rows[0].lyapunov_se_per_impact.fillna(0.0).to_numpy(),
                  rows[1].lyapunov_se_per_impact.fillna(0.0).to_numpy())
    value_se = pd.Series(se).groupby(rows[1][column].to_numpy()).max()
    moved = value_changed.reindex(committed[column]).fillna(True).to_numpy(bool)
    for name in outcome:
        same = (fresh[name].astype(str) == committed[name].astype(str)).to_numpy()
        problems += _problem(where, name, ~(same | moved), " (no late outcome changed there)")
    spread = value_se.reindex(committed[column]).fillna(0.0).to_numpy()
    for name in exponents:
        a, b = fresh[name].to_numpy(float), committed[name].to_numpy(float)
        close = exponents_agree(a, b, spread, 0.0, rtol, atol)
        problems += _problem(where, name, ~(close | moved),
                             f" by more than {Z_EXPONENT:g} standard errors")
    return problems


def thresholds_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                     tables: RunTables, deterministic: Deterministic, rtol: float,
                     atol: float) -> list[str]:
    """``thresholds.csv`` of ``bounce bifurcation``: the onsets of chaos are the first value
    with a chaotic orbit (or a chaotic dominant attractor): they may move only to or from a
    value at which a late outcome changed; every other entry keeps the full tolerance."""
    onset = committed["threshold"].isin(["chaos_onset", "first_chaotic_orbit"]).to_numpy()
    if len(fresh) != len(committed) or not np.array_equal(
            fresh["threshold"].astype(str), committed["threshold"].astype(str)):
        return deterministic(fresh, committed)
    problems = deterministic(fresh[~onset].reset_index(drop=True),
                             committed[~onset].reset_index(drop=True))
    located = next(c for c in committed.columns if c.startswith("located_")
                   and not c.startswith(("located_period1", "located_period2")))
    rows = [tables.fresh["attractors.csv"], tables.committed["attractors.csv"]]
    column = rows[1].columns[0]
    changed = (rows[0].attractor.astype(str) != rows[1].attractor.astype(str)).to_numpy()
    changed_values = np.array(sorted(set(rows[1][column].to_numpy()[changed])), dtype=float)
    for i in np.flatnonzero(onset):
        a, b = float(fresh[located].iloc[i]), float(committed[located].iloc[i])
        if (np.isnan(a) and np.isnan(b)) or np.isclose(a, b, rtol=rtol, atol=atol):
            continue
        # the earlier onset is a value with a chaotic orbit in one run and not the other
        earlier = np.nanmin([a, b])
        if not np.isclose(earlier, changed_values, rtol=rtol, atol=atol).any():
            problems.append(f"{where}: {committed['threshold'].iloc[i]} moved from {b} to {a}, "
                            "and no late outcome changed there")
    return problems


def allowed_flips(undecided: np.ndarray) -> np.ndarray:
    """Basin points that may change class at a parameter point with ``undecided`` points
    still moving when the classification stopped: 1 + 4 sqrt(undecided)."""
    return 1.0 + 4.0 * np.sqrt(np.asarray(undecided, float))


def sweep_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame, tables: RunTables,
                deterministic: Deterministic, rtol: float, atol: float) -> list[str]:
    """``sweep.csv`` of ``bounce sweep``: one row per parameter point, its basin summarised.
    The fractions may move by ``allowed_flips`` points, the boundary boxes by as many, and
    the basin entropies by what so many flips can change (module doc)."""
    fractions = [c for c in committed.columns if c.startswith("fraction_")]
    entropies = ["basin_entropy", "boundary_basin_entropy", "boundary_boxes"]
    fixed = [c for c in committed.columns if c not in fractions + entropies]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    n = committed["basin_points"].to_numpy(float)
    undecided = n * np.maximum(fresh["fraction_undecided"].to_numpy(float),
                               committed["fraction_undecided"].to_numpy(float))
    flips = allowed_flips(undecided)
    for name in fractions:
        moved = np.abs(fresh[name].to_numpy(float) - committed[name].to_numpy(float)) * n
        problems += _problem(where, name, moved > flips + 1e-6,
                             " by more than 1 + 4 sqrt(undecided) points")
    box = int(tables.config.get("measures", {}).get("entropy_box", 5))
    cells = box * box
    per_flip = 2.0 * math.log(cells) / cells if cells > 1 else 0.0  # one box's entropy
    boxes = n / cells  # whole boxes (a grid that is not a multiple of the box has fewer)
    boundary = np.minimum(fresh["boundary_boxes"].to_numpy(float),
                          committed["boundary_boxes"].to_numpy(float))
    with np.errstate(divide="ignore", invalid="ignore"):
        bounds = {
            "boundary_boxes": flips,
            "basin_entropy": flips * per_flip / np.floor(boxes),
            # a flip changes one boundary box's entropy, and may add or remove one (S <= ln m)
            "boundary_basin_entropy": np.where(
                boundary > flips, flips * (per_flip + math.log(cells)) / (boundary - flips),
                np.inf),
        }
    for name, bound in bounds.items():
        moved = np.abs(fresh[name].to_numpy(float) - committed[name].to_numpy(float))
        problems += _problem(where, name, moved > bound + atol,
                             " by more than the allowed flips can change")
    return problems


#: (experiment, table) -> its rule
RULES: dict[tuple[str, str], Callable[..., list[str]]] = {
    ("bifurcation", "attractors.csv"): attractors_drift,
    ("bifurcation", "bifurcation.csv"): bifurcation_points_drift,
    ("bifurcation", "values.csv"): values_drift,
    ("bifurcation", "thresholds.csv"): thresholds_drift,
    ("continuation", "diagram.csv"): diagram_points_drift,
    ("sweep", "sweep.csv"): sweep_drift,
}
