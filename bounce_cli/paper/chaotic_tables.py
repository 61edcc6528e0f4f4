"""What of a chaotic orbit reproduces on another machine: the reproduction rules of the tables
that ``bounce bifurcation``, ``bounce continuation`` and ``bounce sweep`` fill by iterating
the map (eqs. 5, 6) for hundreds of impacts.

A last-bit difference (another libm's sin or cos, another CPU's code path: seen between glibc's
FMA and non-FMA ``sin``) grows by the Lyapunov exponent at every impact of a chaotic orbit and
is of the order of the state after 100-200 impacts. From there on two machines follow two
different orbits of the same attractor: its recorded points, the impact at which a chaotic
transient ends in sticking, and whether it ends before the measurement does are not
reproducible digit for digit, on any two machines. What reproduces is what the attractor and
the statistics of its orbits fix. The rules compare that in two tiers:

* **Each row** where a last bit cannot matter keeps the full tolerance (``reproduce.RTOL``):
  an orbit whose outcome is not late (below) keeps its label, period and sticking impact; a
  periodic orbit its cycle (from any of its impacts: a chaotic transient can end at another
  phase of it); a parameter point with no undecided basin point its fractions, but for one
  point on a boundary.
* **Late outcomes** (``late_outcome``) are an orbit still moving when the run ends
  (``chaotic``, ``unresolved``, or periodic at the longest period looked for: a long or
  chaotic orbit read as periodic) or one that ended only at impact ``LATE_IMPACT`` or later
  (stuck, resting or locked after a chaotic transient or a chatter decided at the 1 ms rule's
  edge). Between two late outcomes the label, period and sticking impact may change, one
  orbit at a time: as many orbits may go from moving to ended as the other way, within
  chance (``balance_drift``: more one way than 4 sqrt(n) + 1 of n is a drift). A last bit
  reshuffles late outcomes; a change of the model moves them one way.
* **Statistics of chaotic orbits** are compared as samples: each difference is divided by its
  standard error (a Lyapunov exponent's from batch means,
  ``analysis.bifurcation.lyapunov_standard_error``; an attractor's pooled points' from batch
  means of ``BATCH`` consecutive impacts; a basin fraction's from its undecided points), and
  the standardised differences z of a table must look like chance (``aggregate_drift``):
  about as many up as down (``balance_drift``), a mean near 0 (each z clipped to +-3, the
  mean within 5 / sqrt(n)), and a median |z| of at most ``MEDIAN_Z`` (chance: about 0.7)
  over at least ``MEDIAN_MIN_UNITS`` of them. One intermittent orbit can
  be far off (an exponent 14 standard errors away was seen: batch means do not see an
  intermittency longer than the run), a systematic change cannot hide: exponents 10 % off,
  an attractor's velocities 5 % off or its phases 10 deg off are drifts.

Measured (runs at g moved by -3..3 ulps, and the whole of ``bounce reproduce`` with glibc's
non-FMA libm: ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``): no sticking impact below 36
changed; late outcomes switched 0 to 3 orbits each way; exponents moved by at most 3.6
combined standard errors (830 pairs); a sweep point changed at most 47 of its 1600 basin
points (993 undecided).
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from ..analysis.bifurcation import detect_period
from ..experiments.bifurcation import IterateBlock
from ..experiments.sweep import MeasuresBlock
from ..model.params import phase_difference
from ..runtime.artifacts import RunTables

#: an orbit that ended (stuck, rested, locked) at this impact or later ended late (measured:
#: with g moved by ulps, no sticking impact below 36 changed)
LATE_IMPACT = 30
#: outcomes of an orbit still moving on a chaotic attractor (or not settled) when it ends
MOVING = ("chaotic", "unresolved")
#: outcomes of an orbit that ended on the racket
ENDED = ("sticking", "resting", "locked")
#: a row that is not late: its exponent within this many combined standard errors
Z_ROW = 6.0
#: more units one way than Z_SIGN sqrt(n) + 1 of n is a drift (chance: < 1e-4)
Z_SIGN = 4.0
#: the mean of a table's standardised differences, each clipped to +-WINSOR (one intermittent
#: orbit weighs no more than 3), at most Z_MEAN / sqrt(n) (chance: the clipped mean of n
#: standard normal z has SD < 1 / sqrt(n))
Z_MEAN, WINSOR = 5.0, 3.0
#: the median |z| of a table's standardised differences at most this (chance: 0.67 for normal
#: z; P(median of 5 > 2.5) ~ 4e-4 even for t with 9 degrees of freedom)
MEDIAN_Z = 2.5
MEDIAN_MIN_UNITS = 5
#: consecutive recorded impacts per batch for the standard errors of an attractor's points
BATCH = 8
#: the period tolerance (m/s and rad) with which the points of an orbit are read as periodic:
#: the experiments' own (``period_tolerance``)
PERIOD_TOLERANCE = 1e-6

#: the deterministic rule of ``reproduce.table_drift`` for some columns: (fresh, committed)
#: -> one line per disagreement
Deterministic = Callable[[pd.DataFrame, pd.DataFrame], list[str]]


# -- chance ------------------------------------------------------------------------------------
def balance_drift(where: str, what: str, up: int, down: int) -> list[str]:
    """A drift when ``up`` and ``down`` (units that changed one way and the other) are more
    unequal than chance allows: |up - down| > Z_SIGN sqrt(up + down) + 1."""
    if abs(up - down) <= Z_SIGN * math.sqrt(up + down) + 1.0:
        return []
    return [f"{where} {what}: {up} one way and {down} the other, more one-sided than a last "
            "bit's reshuffling allows"]


def aggregate_drift(where: str, what: str, z) -> list[str]:
    """A drift when a table's standardised differences ``z`` (one per unit that differs) do
    not look like chance: one-sided (``balance_drift``, or a mean of z clipped to +-WINSOR
    beyond Z_MEAN / sqrt(n)), or a median |z| above MEDIAN_Z."""
    z = np.asarray(z, dtype=float)
    z = z[~np.isnan(z) & (z != 0.0)]
    problems = balance_drift(where, what, int((z > 0).sum()), int((z < 0).sum()))
    if z.size and abs(np.clip(z, -WINSOR, WINSOR).mean()) * math.sqrt(z.size) > Z_MEAN:
        problems.append(f"{where} {what}: mean difference {np.clip(z, -WINSOR, WINSOR).mean():+.3g}"
                        f" standard errors over {z.size}: one-sided beyond chance")
    if z.size >= MEDIAN_MIN_UNITS and np.median(np.abs(z)) > MEDIAN_Z:
        problems.append(f"{where} {what}: median |difference| {np.median(np.abs(z)):.3g} "
                        f"standard errors over {z.size}, more than chance ({MEDIAN_Z:g})")
    return problems


def standardised(a, b, se_a, se_b) -> np.ndarray:
    """(a - b) / sqrt(se_a^2 + se_b^2); 0 where a == b, +-inf where they differ with no
    error to measure it by."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    se = np.hypot(np.nan_to_num(np.asarray(se_a, float)), np.nan_to_num(np.asarray(se_b, float)))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (a - b) / se
    return np.where(a == b, 0.0, z)


def _problem(where: str, column: str, bad: np.ndarray, what: str = "") -> list[str]:
    if not bad.any():
        return []
    return [f"{where} column {column}: {int(bad.sum())} of {bad.size} values drifted from the "
            f"committed baseline{what}; first at row {np.flatnonzero(bad)[:5]}"]


def _close(a, b, rtol: float, atol: float) -> np.ndarray:
    return np.isclose(np.asarray(a, float), np.asarray(b, float), rtol=rtol, atol=atol,
                      equal_nan=True)


# -- bounce bifurcation ------------------------------------------------------------------------
def late_outcome(attractors: pd.DataFrame, max_period: int | None = None) -> np.ndarray:
    """Per row of an ``attractors.csv``: whether its outcome is late (module doc).
    ``max_period``: the longest period the run looked for (``iterate.max_period``)."""
    name = attractors["attractor"].astype(str)
    late = name.isin(MOVING) | (name.isin(ENDED) & (attractors["stuck_at_impact"] >= LATE_IMPACT))
    if "locked_cycles" in attractors:  # exact sticking: when it locked is not recorded
        late |= name == "locked"
    if max_period is not None:
        late |= attractors["period"] == max_period
    return late.to_numpy()


def moving(attractors: pd.DataFrame) -> np.ndarray:
    """Per row: whether the orbit was still moving when the run ended (not stuck, rested or
    locked, and not below the racket)."""
    return ~attractors["attractor"].astype(str).isin(ENDED + ("below_racket",)).to_numpy()


def _keys(frame: pd.DataFrame) -> list[str]:
    """The columns that name an orbit: the swept parameter (first column) and its start."""
    return [frame.columns[0], "initial_condition"]


def _setting(tables: RunTables, default, *path: str):
    """A value of the runs' config (``run.json``'s resolved config), or the experiment's
    default where the config does not hold it."""
    block: object = tables.config
    for key in path:
        block = block.get(key) if isinstance(block, Mapping) else None
    return default if block is None else block


def _max_period(tables: RunTables) -> int:
    return int(_setting(tables, IterateBlock().max_period, "iterate", "max_period"))


def _both_attractors(tables: RunTables) -> tuple[pd.DataFrame, pd.DataFrame] | None:
    """Both runs' ``attractors.csv`` when they hold the same orbits in the same order (else
    the tables that depend on them are compared value by value)."""
    fresh, committed = tables.fresh["attractors.csv"], tables.committed["attractors.csv"]
    keys = _keys(committed)
    if (len(fresh) != len(committed) or list(fresh.columns[:1]) != keys[:1]
            or not all(np.array_equal(fresh[k].to_numpy(), committed[k].to_numpy())
                       for k in keys)):
        return None
    return fresh.reset_index(drop=True), committed.reset_index(drop=True)


def attractors_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                     tables: RunTables, deterministic: Deterministic, rtol: float,
                     atol: float) -> list[str]:
    """``attractors.csv`` of ``bounce bifurcation``: one row per orbit (value x start)."""
    outcome = [c for c in ("attractor", "period", "stuck_at_impact", "locked_cycles")
               if c in committed]
    statistical = outcome + ["lyapunov_per_impact", "lyapunov_se_per_impact"]
    fixed = [c for c in committed.columns if c not in statistical]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    max_period = _max_period(tables)
    late = late_outcome(fresh, max_period) & late_outcome(committed, max_period)
    for column in outcome:
        same = (fresh[column].astype(str) == committed[column].astype(str)).to_numpy()
        problems += _problem(where, column, ~(same | late), " (not a late outcome)")
    went = moving(committed) & ~moving(fresh) & late
    came = ~moving(committed) & moving(fresh) & late
    problems += balance_drift(where, "late outcomes (moving -> ended, ended -> moving)",
                              int(went.sum()), int(came.sum()))

    a, b = fresh.lyapunov_per_impact.to_numpy(float), committed.lyapunov_per_impact.to_numpy(float)
    both = np.isfinite(a) & np.isfinite(b)
    differ = both & ~_close(a, b, rtol, atol)
    z = standardised(a, b, fresh.lyapunov_se_per_impact, committed.lyapunov_se_per_impact)
    problems += _problem(where, "lyapunov_per_impact", differ & ~late & ~(np.abs(z) <= Z_ROW),
                         f" by more than {Z_ROW:g} standard errors (not a late outcome)")
    problems += aggregate_drift(where, "lyapunov_per_impact", z[differ])
    # an exponent where the orbit did not end; -inf (locked) only with itself
    kind = [np.where(np.isfinite(x), 0, np.where(np.isnan(x), 1, np.sign(x) + 3))
            for x in (a, b)]
    problems += _problem(where, "lyapunov_per_impact", (kind[0] != kind[1]) & ~late,
                         " (an exponent in one run only)")
    # the errors themselves are statistics of a statistic (an intermittent orbit's moved by a
    # factor 3.5, a periodic orbit's from 3e-5 to 2e-11 where a transient ended while
    # measured in one run only): only where they exist is compared
    has_se = [np.isfinite(t.lyapunov_se_per_impact.to_numpy(float)) for t in (fresh, committed)]
    problems += _problem(where, "lyapunov_se_per_impact", (has_se[0] != has_se[1]) & ~late,
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
    if vb.size < period or va.size < period:
        return False
    for shift in range(period):
        vs, ts = np.roll(vb[:period], -shift), np.roll(tb[:period], -shift)
        if (np.allclose(vs, va, rtol=rtol, atol=atol)
                and np.all(np.abs(phase_difference(ts, ta)) <= atol + rtol * 2.0 * math.pi)):
            return True
    return False


#: what is compared of an attractor's points at one value: means of v, cos theta, sin theta
#: (the phase's mean direction, no cut on the circle) and |v - the committed mean v| (spread)
POINT_STATISTICS = ("mean v", "mean cos theta", "mean sin theta", "mean |v - centre|")


def point_statistics(orbits: list[pd.DataFrame], centre: float) -> tuple[np.ndarray, np.ndarray]:
    """The POINT_STATISTICS of the recorded points of ``orbits`` (orbits of one attractor at
    one value) and their standard errors by batch means: each orbit's impacts in batches of
    BATCH consecutive ones (a remainder dropped), SD of the batch means / sqrt(batches)."""
    batches = []
    for orbit in orbits:
        v = orbit["v_m_s"].to_numpy(float)
        theta = np.radians(orbit["theta_deg"].to_numpy(float))
        per_point = np.stack([v, np.cos(theta), np.sin(theta), np.abs(v - centre)], axis=1)
        whole = (len(v) // BATCH) * BATCH
        if whole:
            batches.append(per_point[:whole].reshape(-1, BATCH, 4).mean(axis=1))
    if not batches:
        return np.full(4, np.nan), np.full(4, np.nan)
    means = np.concatenate(batches)
    if len(means) < 2:
        return means.mean(axis=0), np.full(4, np.nan)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / math.sqrt(len(means))


def orbit_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                       period_fresh: Mapping[tuple, int], period_committed: Mapping[tuple, int],
                       late: Callable[[tuple], bool], rtol: float, atol: float) -> list[str]:
    """Recorded points of many orbits. ``period_*``: key -> the orbit's period on each side (0:
    aperiodic); ``late(key)``: whether the orbit's outcome is late on both sides. A periodic
    orbit is compared as its cycle; the aperiodic orbits at one value, pooled, by their
    POINT_STATISTICS over all values (``aggregate_drift``); an orbit recorded on one side only,
    or periodic on one and aperiodic on the other, must be late, as many one way as the other."""
    keys = _keys(committed)
    groups_f = dict(tuple(fresh.groupby(keys, sort=False)))
    groups_c = dict(tuple(committed.groupby(keys, sort=False)))
    problems = []
    only = {"fresh": set(groups_f) - set(groups_c), "committed": set(groups_c) - set(groups_f)}
    early = sorted(k for side in only.values() for k in side if not late(k))
    if early:
        problems.append(f"{where}: {len(early)} orbit(s) recorded in one run only, not after a "
                        f"late outcome; first {early[:3]}")
    problems += balance_drift(where, "orbits recorded in one run only (this run, the "
                              "committed)", len(only["fresh"]), len(only["committed"]))
    differ: list[tuple] = []
    pooled: dict[float, tuple[list[pd.DataFrame], list[pd.DataFrame]]] = {}
    for key in sorted(set(groups_f) & set(groups_c)):
        a, b = groups_f[key], groups_c[key]
        pa, pb = period_fresh.get(key, 0), period_committed.get(key, 0)
        if pa and pb:
            ok = pa == pb and len(a) == len(b) and cycles_agree(a, b, pa, rtol, atol)
        elif not pa and not pb:
            pooled.setdefault(key[0], ([], []))
            pooled[key[0]][0].append(a)
            pooled[key[0]][1].append(b)
            continue
        else:
            ok = late(key)
        if not ok:
            differ.append(key)
    if differ:
        problems.append(f"{where}: {len(differ)} orbit(s) drifted from the committed baseline "
                        f"(another cycle, or periodic in one run only); first {differ[:3]}")
    z = []
    for orbits_f, orbits_c in pooled.values():
        centre = float(np.mean(np.concatenate([o["v_m_s"].to_numpy(float) for o in orbits_c])))
        (mean_f, se_f), (mean_c, se_c) = (point_statistics(o, centre)
                                          for o in (orbits_f, orbits_c))
        z.append(standardised(mean_f, mean_c, se_f, se_c))
    for i, name in enumerate(POINT_STATISTICS):
        problems += aggregate_drift(where, f"aperiodic orbits' {name}", [row[i] for row in z])
    return problems


def bifurcation_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                             tables: RunTables, deterministic: Deterministic, rtol: float,
                             atol: float) -> list[str]:
    """``bifurcation.csv``: each orbit's recorded points, read as its ``attractors.csv`` row
    says (its period; aperiodic when chaotic or unresolved)."""
    both = _both_attractors(tables)
    if both is None:
        return deterministic(fresh, committed)
    keys = _keys(both[1])
    names = list(zip(*(both[1][k] for k in keys)))
    periods = [dict(zip(names, t["period"].astype(int))) for t in both]
    max_period = _max_period(tables)
    late = dict(zip(names, late_outcome(both[0], max_period) & late_outcome(both[1], max_period)))
    return orbit_points_drift(where, fresh, committed, periods[0], periods[1],
                              lambda key: bool(late.get(key, False)), rtol, atol)


def diagram_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                         tables: RunTables, deterministic: Deterministic, rtol: float,
                         atol: float) -> list[str]:
    """``diagram.csv`` of ``bounce continuation``: each orbit's period read from its points
    (the longest looked for: half the recorded impacts); an orbit is late where it is
    aperiodic or at that longest period, or missing (it stuck), on each side."""
    keys = _keys(committed)
    if list(fresh.columns) != list(committed.columns) or keys[1] not in committed:
        return deterministic(fresh, committed)
    sides = []
    for table in (fresh, committed):
        groups = dict(tuple(table.groupby(keys, sort=False)))
        sides.append(({key: _period_of(g) for key, g in groups.items()},
                      {key: len(g) // 2 for key, g in groups.items()}))

    def late_on(side, key) -> bool:
        periods, longest = side
        return key not in periods or periods[key] in (0, longest[key])

    return orbit_points_drift(where, fresh, committed, sides[0][0], sides[1][0],
                              lambda key: late_on(sides[0], key) and late_on(sides[1], key),
                              rtol, atol)


def _changed_values(both: tuple[pd.DataFrame, pd.DataFrame]) -> np.ndarray:
    """The swept values at which some orbit's outcome changed between the runs."""
    changed = (both[0].attractor.astype(str) != both[1].attractor.astype(str)).to_numpy()
    return np.unique(both[1].iloc[:, 0].to_numpy(float)[changed])


def values_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame, tables: RunTables,
                 deterministic: Deterministic, rtol: float, atol: float) -> list[str]:
    """``values.csv`` of ``bounce bifurcation``: one row per value, summarising its orbits
    (``attractors.csv``). Where some orbit's late outcome changed, the outcome columns may
    differ; the exponents (a maximum and a mean of the orbits' exponents) within Z_ROW times
    the largest combined standard error of that value's orbits where no orbit is late, and
    like chance over all values (``aggregate_drift``)."""
    outcome = ["attractors", "dominant_attractor", "n_sticking"]
    exponents = ["lyapunov_max_per_impact", "lyapunov_dominant_per_impact"]
    fixed = [c for c in committed.columns if c not in outcome + exponents]
    problems = deterministic(fresh[fixed], committed[fixed])
    both = _both_attractors(tables)
    if problems or len(fresh) != len(committed) or both is None:
        return problems or deterministic(fresh, committed)
    column = committed.columns[0]
    value_of_row = both[1][column].to_numpy(float)
    max_period = _max_period(tables)
    late_rows = late_outcome(both[0], max_period) | late_outcome(both[1], max_period)
    values = committed[column].to_numpy(float)
    moved = np.isin(values, _changed_values(both))
    has_late = np.isin(values, np.unique(value_of_row[late_rows]))
    for name in outcome:
        same = (fresh[name].astype(str) == committed[name].astype(str)).to_numpy()
        problems += _problem(where, name, ~(same | moved), " (no late outcome changed there)")
    se = np.hypot(both[0].lyapunov_se_per_impact.fillna(0.0).to_numpy(),
                  both[1].lyapunov_se_per_impact.fillna(0.0).to_numpy())
    spread = pd.Series(se).groupby(value_of_row).max().reindex(values).fillna(0.0).to_numpy()
    for name in exponents:
        a, b = fresh[name].to_numpy(float), committed[name].to_numpy(float)
        differ = ~_close(a, b, rtol, atol) & ~moved
        z = standardised(a, b, spread, 0.0)
        problems += _problem(where, name, differ & ~has_late & ~(np.abs(z) <= Z_ROW),
                             f" by more than {Z_ROW:g} standard errors")
        problems += aggregate_drift(where, name, z[differ])
    return problems


def thresholds_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                     tables: RunTables, deterministic: Deterministic, rtol: float,
                     atol: float) -> list[str]:
    """``thresholds.csv`` of ``bounce bifurcation``: the onsets of chaos are the first value
    with a chaotic orbit (or a chaotic dominant attractor): they may move only to or from a
    value at which a late outcome changed; every other entry keeps the full tolerance."""
    onset = committed["threshold"].isin(["chaos_onset", "first_chaotic_orbit"]).to_numpy()
    both = _both_attractors(tables)
    if (both is None or len(fresh) != len(committed) or not np.array_equal(
            fresh["threshold"].astype(str), committed["threshold"].astype(str))):
        return deterministic(fresh, committed)
    problems = deterministic(fresh[~onset].reset_index(drop=True),
                             committed[~onset].reset_index(drop=True))
    located = next(c for c in committed.columns if c.startswith("located_")
                   and not c.startswith(("located_period1", "located_period2")))
    changed_values = _changed_values(both)
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


# -- bounce sweep ------------------------------------------------------------------------------
def allowed_flips(undecided) -> np.ndarray:
    """Basin points that may change class at a parameter point with ``undecided`` points
    still moving when the classification stopped: 1 + 4 sqrt(undecided) (the net change of
    a class among n points each flipping with probability p has SD sqrt(2 n p (1 - p)) <=
    0.71 sqrt(n): this is at least 5.7 SD; the one is a point on a basin boundary)."""
    return 1.0 + 4.0 * np.sqrt(np.asarray(undecided, float))


def sweep_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame, tables: RunTables,
                deterministic: Deterministic, rtol: float, atol: float) -> list[str]:
    """``sweep.csv`` of ``bounce sweep``: one row per parameter point, its basin summarised.
    Per point the fractions may move by ``allowed_flips`` points, the boundary boxes by as
    many, the basin entropies by what so many flips can change (one flip changes one box's
    Gibbs entropy by at most 2 ln(m)/m for m cells a box, and a boundary box's entropy is at
    most ln of the number of outcomes), the uncertainty exponent by Z_ROW of its standard
    errors; over all points each like chance (``aggregate_drift``)."""
    fractions = [c for c in committed.columns if c.startswith("fraction_")]
    entropies = ["basin_entropy", "boundary_basin_entropy", "boundary_boxes"]
    uncertainty = [c for c in ("uncertainty_exponent", "uncertainty_exponent_se")
                   if c in committed]
    fixed = [c for c in committed.columns if c not in fractions + entropies + uncertainty]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    n = committed["basin_points"].to_numpy(float)
    undecided = n * np.maximum(fresh["fraction_undecided"].to_numpy(float),
                               committed["fraction_undecided"].to_numpy(float))
    flips = allowed_flips(undecided)
    scale = np.sqrt(undecided + 1.0)  # the standard error of a count, at most (see above)
    for name in fractions:
        moved = (fresh[name].to_numpy(float) - committed[name].to_numpy(float)) * n
        problems += _problem(where, name, np.abs(moved) > flips + 1e-6,
                             " by more than 1 + 4 sqrt(undecided) points")
        problems += aggregate_drift(where, name, moved / scale)

    box = int(_setting(tables, MeasuresBlock().entropy_box, "measures", "entropy_box"))
    cells = box * box
    grid = [_setting(tables, None, "basin", axis, "num") for axis in ("theta0_deg", "v0_m_s")]
    boxes = (math.prod(int(num) // box for num in grid) if all(grid)
             else np.floor(n / cells))  # whole boxes only
    per_flip = 2.0 * math.log(cells) / cells if cells > 1 else 0.0  # one box's entropy
    outcomes = max(len(fractions), 2)
    boundary = np.minimum(fresh["boundary_boxes"].to_numpy(float),
                          committed["boundary_boxes"].to_numpy(float))
    with np.errstate(divide="ignore", invalid="ignore"):
        bounds = {
            "boundary_boxes": flips,
            "basin_entropy": flips * per_flip / boxes,
            # a flip changes one boundary box's entropy, and may add or remove one
            # (its entropy at most ln(outcomes))
            "boundary_basin_entropy": np.where(
                boundary > flips,
                flips * (per_flip + math.log(min(cells, outcomes))) / (boundary - flips),
                np.inf),
        }
    for name, bound in bounds.items():
        moved = fresh[name].to_numpy(float) - committed[name].to_numpy(float)
        problems += _problem(where, name, np.abs(moved) > bound + atol,
                             " by more than the allowed flips can change")
        problems += aggregate_drift(where, name, moved / (bound / flips * scale))
    if "uncertainty_exponent" in uncertainty:
        a, b = (t["uncertainty_exponent"].to_numpy(float) for t in (fresh, committed))
        z = standardised(a, b, fresh.get("uncertainty_exponent_se"),
                         committed.get("uncertainty_exponent_se"))
        differ = ~_close(a, b, rtol, atol)
        problems += _problem(where, "uncertainty_exponent", differ & ~(np.abs(z) <= Z_ROW),
                             f" by more than {Z_ROW:g} standard errors")
        problems += aggregate_drift(where, "uncertainty_exponent", z[differ])
    return problems


def uncertainty_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                      tables: RunTables, deterministic: Deterministic, rtol: float,
                      atol: float) -> list[str]:
    """``uncertainty.csv`` of ``bounce sweep``: the fraction of ``measures.samples`` random
    points whose outcome changes at each eps, within Z_ROW binomial standard errors, and
    like chance over all rows."""
    fixed = [c for c in committed.columns if c != "uncertain_fraction"]
    problems = deterministic(fresh[fixed], committed[fixed])
    samples = int(_setting(tables, MeasuresBlock().samples, "measures", "samples"))
    if problems or len(fresh) != len(committed):
        return problems
    a, b = (t["uncertain_fraction"].to_numpy(float) for t in (fresh, committed))
    se = [np.sqrt(np.maximum(f * (1.0 - f), 1.0 / samples) / samples) for f in (a, b)]
    z = standardised(a, b, se[0], se[1])
    differ = ~_close(a, b, rtol, atol)
    problems += _problem(where, "uncertain_fraction", differ & ~(np.abs(z) <= Z_ROW),
                         f" by more than {Z_ROW:g} standard errors")
    return problems + aggregate_drift(where, "uncertain_fraction", z[differ])


#: (experiment, table) -> its rule
RULES: dict[tuple[str, str], Callable[..., list[str]]] = {
    ("bifurcation", "attractors.csv"): attractors_drift,
    ("bifurcation", "bifurcation.csv"): bifurcation_points_drift,
    ("bifurcation", "values.csv"): values_drift,
    ("bifurcation", "thresholds.csv"): thresholds_drift,
    ("continuation", "diagram.csv"): diagram_points_drift,
    ("sweep", "sweep.csv"): sweep_drift,
    ("sweep", "uncertainty.csv"): uncertainty_drift,
}
