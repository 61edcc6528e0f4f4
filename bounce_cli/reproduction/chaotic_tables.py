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
  phase of it); a parameter point without late basin points its fractions, but for one point
  on a boundary.
* **Late outcomes** (``late_outcome``) are an orbit still moving when the run ends
  (``chaotic``, ``unresolved``, or periodic at the longest period looked for: a long or
  chaotic orbit read as periodic) or one on whose way a perturbation of the start grew by
  ``LATE_STRETCH`` (``peak_stretch``, recorded by the run: a last bit grown to 1e-6; a
  chaotic transient, or a chatter decided at the edge of the 1 ms rule, before it stuck or
  settled on a periodic orbit). Between two late outcomes the label, period and sticking
  impact may change, one orbit at a time: as many orbits may go from moving to ended, and
  from periodic to ended, as the other way, within chance (``balance_drift``: more one way
  than 5 sqrt(n) + 1 of n is a drift). A last bit reshuffles late outcomes; a change of the
  model moves them one way.
* **Statistics of chaotic orbits** are compared as samples: each difference is divided by its
  standard error (a Lyapunov exponent's from batch means,
  ``analysis.bifurcation.lyapunov_standard_error``; an attractor's pooled points' from batch
  means of ``BATCH`` consecutive impacts; a basin fraction's from its late points), and the
  standardised differences z of a table must look like chance (``aggregate_drift``): about
  as many up as down (``balance_drift``), a mean near 0 (each z clipped to +-3, the mean
  within 5 / sqrt(n)), and a median |z| of at most ``MEDIAN_Z`` (chance: about 0.7) over at
  least ``MEDIAN_MIN_UNITS`` of them. One intermittent orbit can be far off (an exponent 14
  standard errors away was seen: batch means do not see an intermittency longer than the
  run), a systematic change cannot hide: exponents 3 % off, an attractor's velocities 0.5 %
  off or its phases mirrored are drifts.

Measured (the bundled bifurcation with g moved by -8..8 ulps, continuation by -6..6, sweep by
-4..4, and the whole of ``bounce reproduce`` with glibc's non-FMA libm,
``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``): no outcome changed where ``peak_stretch`` was
below 28.7 on either machine; late outcomes switched 0 to 4 orbits each way; exponents moved
by at most 3.9 combined standard errors, 78 of 118 one way at most; a sweep point changed at
most 47 of its 1600 basin points (993 undecided); every test of chance stayed within 0.7 of
its limit.
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from ..experiments.bifurcation import IterateBlock
from ..experiments.sweep import MeasuresBlock
from ..model.params import phase_difference
from ..runtime.artifacts import RunTables

#: the precision of ``peak_stretch``: the log growth of an impact that nearly grazes the
#: racket (a chatter's last ones before the 1 ms rule) takes the last bits of a tiny approach
#: velocity (measured, with g moved by up to 8 ulps: relative differences up to 7e-5)
STRETCH_RTOL = 1e-3
#: an orbit whose start's perturbations grew by this much (ln) or more has a late outcome: a
#: last bit (1.1e-16 relative) grew to 1e-6, the scale of the period tolerance and of the
#: reproduction tolerance (measured: outcomes changed with g moved by ulps only where
#: ``peak_stretch`` was 28.7 or more on both machines)
LATE_STRETCH = math.log(1e-6 / 1.1e-16)
#: outcomes of an orbit still moving on a chaotic attractor (or not settled) when it ends
MOVING = ("chaotic", "unresolved")
#: outcomes of an orbit that ended on the racket (a locked orbit, exact sticking's, is a cycle
#: through its sticks: recorded, and periodic here)
ENDED = ("sticking", "resting")
#: a row that is not late: its exponent within this many combined standard errors
Z_ROW = 6.0
#: more units one way than Z_SIGN sqrt(n) + 1 of n is a drift (chance: < 1e-6 for independent
#: units; measured over 17 runs with g moved by ulps: at most 78 of 118 exponents one way,
#: 3.5 sqrt(n))
Z_SIGN = 5.0
#: the mean of a table's standardised differences, each clipped to +-WINSOR (one intermittent
#: orbit weighs no more than 3), at most Z_MEAN / sqrt(n) (chance: the clipped mean of n
#: standard normal z has SD < 1 / sqrt(n))
Z_MEAN, WINSOR = 5.0, 3.0
#: the median |z| of a table's standardised differences at most this (chance: 0.67 for normal
#: z; P(median of 5 > 2.5) ~ 4e-4 even for t with 9 degrees of freedom)
MEDIAN_Z = 2.5
MEDIAN_MIN_UNITS = 5
#: the SD of the ln of the ratio of two batch-means errors of 10 batches each, and errors
#: below which an exponent is known to rounding (a periodic orbit with real multipliers)
SE_LOG_RATIO_SD, SE_ROUNDING = 0.35, 1e-9
#: consecutive recorded impacts per batch for the standard errors of an attractor's points
BATCH = 8
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
    """(a - b) / sqrt(se_a^2 + se_b^2): 0 where a == b; NaN where an error is unknown (NaN:
    too few batches to tell; the unit then counts in no test of chance), +-inf where both
    errors are 0 and the values differ."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    se = np.hypot(np.asarray(se_a, float), np.asarray(se_b, float))
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
    """Per row of an ``attractors.csv``: whether its outcome is late (module doc): the orbit
    still moves chaotically (or has not settled, or shows the longest period looked for,
    ``max_period``), or a perturbation of its start grew by ``LATE_STRETCH`` or more on the
    way to its outcome (``peak_stretch``: a chaotic transient, a chatter at the edge)."""
    name = attractors["attractor"].astype(str)
    late = name.isin(MOVING) | (attractors["peak_stretch"] >= LATE_STRETCH)
    if max_period is not None:
        late |= attractors["period"] == max_period
    return late.to_numpy()


def fate(attractors: pd.DataFrame) -> np.ndarray:
    """Per row: how the orbit ended, ``ended`` (stuck, rested), ``periodic`` (a cycle, locked
    ones included), ``moving`` (chaotic, unresolved) or ``other`` (below the racket)."""
    name = attractors["attractor"].astype(str)
    cycle = (attractors["period"] > 0) | (name == "locked")
    return np.select([name.isin(ENDED).to_numpy(), cycle.to_numpy(),
                      name.isin(MOVING).to_numpy()], ["ended", "periodic", "moving"], "other")


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
    """The longest period the runs looked for: ``iterate.max_period`` (bounce bifurcation),
    half of ``diagram.recorded_impacts`` (bounce continuation's diagram), else the default."""
    recorded = _setting(tables, None, "diagram", "recorded_impacts")
    if recorded is not None:
        return int(recorded) // 2
    return int(_setting(tables, IterateBlock().max_period, "iterate", "max_period"))


def _both_attractors(tables: RunTables, name: str = "attractors.csv"
                     ) -> tuple[pd.DataFrame, pd.DataFrame] | None:
    """Both runs' table of orbits (``attractors.csv``) when they hold the same columns and
    the same orbits in the same order (else, results of another version among them, the
    tables that depend on it are compared value by value)."""
    try:
        fresh, committed = tables.fresh[name], tables.committed[name]
    except KeyError:
        return None
    keys = _keys(committed)
    if (list(fresh.columns) != list(committed.columns) or "peak_stretch" not in committed
            or len(fresh) != len(committed)
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
    statistical = outcome + ["lyapunov_per_impact", "lyapunov_se_per_impact", "peak_stretch"]
    fixed = [c for c in committed.columns if c not in statistical]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    max_period = _max_period(tables)
    late = late_outcome(fresh, max_period) & late_outcome(committed, max_period)
    for column in outcome:
        same = (fresh[column].astype(str) == committed[column].astype(str)).to_numpy()
        problems += _problem(where, column, ~(same | late), " (not a late outcome)")
    stretch = [t.peak_stretch.to_numpy(float) for t in (fresh, committed)]
    problems += _problem(where, "peak_stretch",
                         ~(_close(stretch[0], stretch[1], STRETCH_RTOL, atol) | late),
                         f" by more than {STRETCH_RTOL:g} relative (not a late outcome)")
    fates = [fate(t) for t in (fresh, committed)]
    for one, other in (("moving", "ended"), ("periodic", "ended"), ("moving", "periodic")):
        went = (fates[1] == one) & (fates[0] == other) & late
        came = (fates[1] == other) & (fates[0] == one) & late
        problems += balance_drift(where, f"late outcomes ({one} -> {other}, {other} -> {one})",
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
    # measured in one run only): where they exist, and their ratios over the table like
    # chance (the ln of a ratio of two 10-batch errors has an SD of about 0.35)
    se = [t.lyapunov_se_per_impact.to_numpy(float) for t in (fresh, committed)]
    problems += _problem(where, "lyapunov_se_per_impact",
                         (np.isfinite(se[0]) != np.isfinite(se[1])) & ~late,
                         " (missing in one run)")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.log(se[0] / se[1])
    measured = (np.fmax(se[0], se[1]) > SE_ROUNDING) & ~_close(se[0], se[1], rtol, atol)
    problems += aggregate_drift(where, "lyapunov_se_per_impact (ln ratio)",
                                ratio[measured & np.isfinite(ratio)] / SE_LOG_RATIO_SD)
    return problems


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
#: (the phase's mean direction, no cut on the circle), |v - c| (spread) and (v - c) cos theta,
#: (v - c) sin theta (how velocity and phase go together), c the committed mean v
POINT_STATISTICS = ("mean v", "mean cos theta", "mean sin theta", "mean |v - c|",
                    "mean (v - c) cos theta", "mean (v - c) sin theta")


def point_statistics(orbits: list[pd.DataFrame], centre: float) -> tuple[np.ndarray, np.ndarray]:
    """The POINT_STATISTICS of the recorded points of ``orbits`` (orbits of one attractor at
    one value) and their standard errors by batch means: each orbit's impacts in batches of
    BATCH consecutive ones (a remainder dropped), SD of the batch means / sqrt(batches); NaN
    errors with fewer than two batches."""
    batches = []
    for orbit in orbits:
        v = orbit["v_m_s"].to_numpy(float)
        theta = np.radians(orbit["theta_deg"].to_numpy(float))
        cos, sin, dv = np.cos(theta), np.sin(theta), v - centre
        per_point = np.stack([v, cos, sin, np.abs(dv), dv * cos, dv * sin], axis=1)
        whole = (len(v) // BATCH) * BATCH
        if whole:
            batches.append(per_point[:whole].reshape(-1, BATCH, per_point.shape[1]).mean(axis=1))
    count = len(POINT_STATISTICS)
    if not batches:
        return np.full(count, np.nan), np.full(count, np.nan)
    means = np.concatenate(batches)
    if len(means) < 2:
        return means.mean(axis=0), np.full(count, np.nan)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / math.sqrt(len(means))


def orbit_points_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame,
                       orbits: tuple[pd.DataFrame, pd.DataFrame], max_period: int,
                       rtol: float, atol: float) -> list[str]:
    """Recorded points of many orbits, read as their table of orbits (``orbits``: both runs'
    ``attractors.csv``, in the same order) says. A periodic orbit is compared as its cycle;
    the aperiodic orbits at one value, pooled, by their POINT_STATISTICS, over all values like
    chance (``aggregate_drift``); an orbit recorded in one run only (it ended in the other),
    or periodic in one and aperiodic in the other, must be late on both sides (and then as
    many one way as the other: ``attractors_drift``). Each orbit's impacts are the same."""
    keys = _keys(committed)
    late = dict(zip(zip(*(orbits[1][k] for k in keys)),
                    late_outcome(orbits[0], max_period) & late_outcome(orbits[1], max_period)))
    periods = [dict(zip(zip(*(t[k] for k in keys)), t["period"].astype(int))) for t in orbits]
    groups_f = dict(tuple(fresh.groupby(keys, sort=False)))
    groups_c = dict(tuple(committed.groupby(keys, sort=False)))
    problems = []
    for side, groups, table in (("this run", groups_f, orbits[0]), ("committed", groups_c,
                                                                    orbits[1])):
        flew = {key for key, f in zip(zip(*(table[k] for k in keys)), fate(table))
                if f in ("moving", "periodic")}
        if set(groups) != flew:
            problems.append(f"{where}: the orbits recorded ({side}) are not those its table of "
                            f"orbits says did not end ({len(set(groups) ^ flew)} differ)")
    early = sorted(k for k in set(groups_f) ^ set(groups_c) if not late.get(k, False))
    if early:
        problems.append(f"{where}: {len(early)} orbit(s) recorded in one run only, not after a "
                        f"late outcome; first {early[:3]}")
    differ: list[tuple] = []
    pooled: dict[float, tuple[list[pd.DataFrame], list[pd.DataFrame]]] = {}
    for key in sorted(set(groups_f) & set(groups_c)):
        a, b = groups_f[key], groups_c[key]
        pa, pb = periods[0].get(key, 0), periods[1].get(key, 0)
        if "impact" in b and not np.array_equal(a.get("impact"), b["impact"]):
            ok = False
        elif pa and pb:  # a chaotic transient may end on another (coexisting) cycle
            ok = (pa == pb and len(a) == len(b) and cycles_agree(a, b, pa, rtol, atol)
                  or late.get(key, False))
        elif not pa and not pb:
            ok = len(a) == len(b)
            pooled.setdefault(key[0], ([], []))
            pooled[key[0]][0].append(a)
            pooled[key[0]][1].append(b)
        else:
            ok = late.get(key, False)
        if not ok:
            differ.append(key)
    if differ:
        problems.append(f"{where}: {len(differ)} orbit(s) drifted from the committed baseline "
                        f"(another cycle or other impacts, or periodic in one run only); "
                        f"first {differ[:3]}")
    z = []
    for orbits_f, orbits_c in pooled.values():
        centre = float(np.mean(np.concatenate([o["v_m_s"].to_numpy(float) for o in orbits_c])))
        (mean_f, se_f), (mean_c, se_c) = (point_statistics(o, centre)
                                          for o in (orbits_f, orbits_c))
        z.append(standardised(mean_f, mean_c, se_f, se_c))
    for i, name in enumerate(POINT_STATISTICS):
        problems += aggregate_drift(where, f"aperiodic orbits' {name}", [row[i] for row in z])
    return problems


def points_drift(orbits_table: str) -> Callable[..., list[str]]:
    """The rule of a table of recorded impacts (``bifurcation.csv``, continuation's
    ``diagram.csv``) read beside its table of orbits ``orbits_table``."""
    def rule(where: str, fresh: pd.DataFrame, committed: pd.DataFrame, tables: RunTables,
             deterministic: Deterministic, rtol: float, atol: float) -> list[str]:
        both = _both_attractors(tables, orbits_table)
        if both is None or list(committed.columns[:2]) != _keys(both[1]):
            return deterministic(fresh, committed)
        return orbit_points_drift(where, fresh, committed, both, _max_period(tables), rtol,
                                  atol)
    return rule


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
    se = pd.Series(np.hypot(both[0].lyapunov_se_per_impact.fillna(0.0).to_numpy(),
                            both[1].lyapunov_se_per_impact.fillna(0.0).to_numpy()))
    # a maximum over a value's orbits moves by at most the largest of their differences; the
    # dominant attractor's mean exponent has the error of a mean over its orbits
    on_dominant = (both[1].attractor.astype(str).to_numpy() == pd.Series(
        committed["dominant_attractor"].astype(str).to_numpy(), index=values
    ).reindex(value_of_row).to_numpy())
    of_mean = (se[on_dominant] ** 2).groupby(value_of_row[on_dominant]).mean() ** 0.5 / (
        pd.Series(on_dominant).groupby(value_of_row).sum()[lambda k: k > 0] ** 0.5)
    spread = {"lyapunov_max_per_impact": se.groupby(value_of_row).max(),
              "lyapunov_dominant_per_impact": of_mean}
    for name in exponents:
        a, b = fresh[name].to_numpy(float), committed[name].to_numpy(float)
        differ = ~_close(a, b, rtol, atol) & ~moved
        z = standardised(a, b, spread[name].reindex(values).fillna(0.0).to_numpy(), 0.0)
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
def allowed_flips(late_points) -> np.ndarray:
    """Basin points that may change class at a parameter point with ``late_points`` points a
    last bit can decide (``points_decided_late``: undecided, or decided late by a chaotic
    transient): 1 + 4 sqrt(late_points) (the net change of a class among n points each
    flipping with probability p has SD sqrt(2 n p (1 - p)) <= 0.71 sqrt(n): this is at
    least 5.7 SD; the one is a point on a basin boundary)."""
    return 1.0 + 4.0 * np.sqrt(np.asarray(late_points, float))


def sweep_drift(where: str, fresh: pd.DataFrame, committed: pd.DataFrame, tables: RunTables,
                deterministic: Deterministic, rtol: float, atol: float) -> list[str]:
    """``sweep.csv`` of ``bounce sweep``: one row per parameter point, its basin summarised.
    Per point the fractions may move by ``allowed_flips`` points, the boundary boxes by as
    many, the basin entropies by what so many flips can change (one flip changes one box's
    Gibbs entropy by at most 2 ln(m)/m for m cells a box, and a boundary box's entropy is at
    most ln of the number of outcomes), the uncertainty exponent by Z_ROW of its standard
    errors; over all points each like chance (``aggregate_drift``). With exact sticking,
    every ball that sticks at a point rides to one release and shares that ball's fate, a
    chaotic orbit's: where ``locked_cycles`` changed, the point's fractions and entropies
    may change, as many points one way as the other."""
    fractions = [c for c in committed.columns if c.startswith("fraction_")]
    entropies = ["basin_entropy", "boundary_basin_entropy", "boundary_boxes"]
    uncertainty = [c for c in ("uncertainty_exponent", "uncertainty_exponent_se")
                   if c in committed]
    statistical = fractions + entropies + uncertainty + ["points_decided_late", "locked_cycles"]
    fixed = [c for c in committed.columns if c not in statistical]
    problems = deterministic(fresh[fixed], committed[fixed])
    if problems or len(fresh) != len(committed):
        return problems
    n = committed["basin_points"].to_numpy(float)
    late_column = ("points_decided_late" if "points_decided_late" in committed
                   else "fraction_undecided")
    scale_of = n if late_column == "fraction_undecided" else 1.0
    late = np.maximum(fresh[late_column].to_numpy(float),
                      committed[late_column].to_numpy(float)) * scale_of
    problems += _problem(where, late_column, np.abs(
        fresh[late_column].to_numpy(float) - committed[late_column].to_numpy(float))
        * scale_of > allowed_flips(late) + 1e-6, " by more than 1 + 4 sqrt(late points)")
    flips = allowed_flips(late)
    scale = np.sqrt(late + 1.0)  # the standard error of a count, at most (see above)
    released = np.zeros(len(committed), dtype=bool)
    if "locked_cycles" in committed:
        locked = [t["locked_cycles"].to_numpy(float) for t in (fresh, committed)]
        released = locked[0] != locked[1]
        problems += balance_drift(where, "locked orbits (found, lost)",
                                  int(((locked[1] == 0) & released).sum()),
                                  int(((locked[0] == 0) & released).sum()))
    for name in fractions:
        moved = (fresh[name].to_numpy(float) - committed[name].to_numpy(float)) * n
        problems += _problem(where, name, (np.abs(moved) > flips + 1e-6) & ~released,
                             " by more than 1 + 4 sqrt(late points)")
        problems += aggregate_drift(where, name, (moved / scale)[~released])

    box = int(_setting(tables, MeasuresBlock().entropy_box, "measures", "entropy_box"))
    cells = box * box
    grid = [_setting(tables, None, "basin", axis, "num") for axis in ("theta0_deg", "v0_m_s")]
    boxes = (math.prod(int(num) // box for num in grid) if all(grid)
             else np.floor(n / cells))  # whole boxes only
    per_flip = 2.0 * math.log(cells) / cells if cells > 1 else 0.0  # one box's entropy
    most = math.log(min(cells, max(len(fractions), 2)))  # a box's entropy at most
    boundary = np.minimum(fresh["boundary_boxes"].to_numpy(float),
                          committed["boundary_boxes"].to_numpy(float))
    # what one point changing class can change: a box's entropy (by at most per_flip), the
    # number of boundary boxes (by one), and the boundary boxes' mean entropy (one box's
    # entropy, and whether a box is a boundary box: at most ln(outcomes) more)
    each = {"boundary_boxes": np.ones_like(n),
            "basin_entropy": per_flip / boxes * np.ones_like(n),
            "boundary_basin_entropy": per_flip / np.maximum(boundary, 1.0)}
    worst = {**each, "boundary_basin_entropy": np.where(
        boundary > flips, (per_flip + most) / np.maximum(boundary - flips, 1.0), np.inf)}
    for name in each:
        moved = fresh[name].to_numpy(float) - committed[name].to_numpy(float)
        bound = np.minimum(flips * worst[name], most if "entropy" in name else np.inf)
        problems += _problem(where, name, (np.abs(moved) > bound + atol) & ~released,
                             " by more than the allowed flips can change")
        problems += aggregate_drift(where, name, (moved / (each[name] * scale))[~released])
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
    ("bifurcation", "bifurcation.csv"): points_drift("attractors.csv"),
    ("bifurcation", "values.csv"): values_drift,
    ("bifurcation", "thresholds.csv"): thresholds_drift,
    ("continuation", "diagram.csv"): points_drift("diagram_orbits.csv"),
    ("continuation", "diagram_orbits.csv"): attractors_drift,
    ("sweep", "sweep.csv"): sweep_drift,
    ("sweep", "uncertainty.csv"): uncertainty_drift,
}
