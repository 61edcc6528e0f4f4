"""Attractors found, not guessed: every start of a basin named by the attractor it reaches.

Section 3 classifies each start of Fig. 4 by stopping rules (period-1, sticking, below the
racket) and leaves the rest "undecided": a chaotic attractor, a higher-period orbit and a long
transient all look the same there. Here the attractors themselves are found, as Datseris &
Wagemakers (2022, Chaos 32, 023104: ``AttractorsViaRecurrences``) find them for smooth
systems: the state space (theta mod 2 pi, v) is cut into cells, and an orbit that keeps coming
back to the same cells has found an attractor; a later orbit that stays ``consecutive`` impacts
in the cells of a known attractor is in its basin.

The recurrence is run over all starts at once (the map's step protocol, one vectorised
first-impact solve per impact, as the basin's classifier does), in two passes:

1. **Discovery** (on a random sample of the starts, and later on whatever pass 2 leaves):
   windows of ``window`` recorded impacts, up to ``transient + window`` impacts in all. An
   orbit whose last 2 ``max_period`` impacts of a window repeat with a period p <=
   ``max_period`` (v and the wrapped phase within ``period_tolerance``,
   ``bifurcation.detect_period``) is on a period-p orbit; the orbits found are told apart by
   their points (within 100 ``same_orbit``), refined by Newton on F^p (the monodromy of
   ``continuation.evaluate_orbit``) and given their multipliers. An orbit still without a
   period then has recurred when it keeps landing in cells it visited before: the cells
   such orbits share make one attractor (connected components of the cells they visit
   together), a chaotic one where its largest Lyapunov exponent (``bifurcation.iterate_sweep``)
   is positive. Recurrence is Datseris & Wagemakers' criterion: ``recurrence`` impacts in a
   row in cells the orbit had visited, within ``recurrence_impacts``. An orbit that neither
   repeats nor recurs is undecided.
2. **Labelling** (every start): the starts advance together; a start whose state stays
   ``consecutive`` impacts in a row in the cells of one attractor is in that attractor's
   basin. A start that sticks (a hop shorter than ``min_hop_s``, section 3) is ``sticking``;
   with exact sticking (``min_hop_s`` 0, ``model.chatter``) every orbit that sticks is
   released in one state, so it takes the released ball's attractor (the locked orbit, the
   period-1 orbit, or rest). A start that cannot leave the racket is ``below_racket``. Starts
   not labelled within ``max_impacts`` go through discovery themselves; what is still open
   then is undecided, counted and reported.

Labels: an attractor's index (0, 1, ...), or one of the negative codes ``UNDECIDED``,
``BELOW_RACKET``, ``STICKING``, ``RESTING``.
"""

from __future__ import annotations

import builtins
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ..model.chatter import iterate_exact_orbit, release_fate, release_phase
from ..model.impact import MAX_SAFE_STEPS
from ..model.maps import PassiveMap, State
from ..model.params import MIN_HOP_S, ModelError, ModelParams, phase_difference
from .bifurcation import SweepSettings, detect_period, iterate_sweep, sweep_parameters
from .classify import DEFAULT_TILE_POINTS, compiled_kernel_available, tile_slices
from .continuation import evaluate_orbit

TWO_PI = 2.0 * math.pi

#: labels that are not an attractor's index
UNDECIDED, BELOW_RACKET, STICKING, RESTING = -1, -2, -3, -4
#: their names, by code
OTHER_LABELS = {UNDECIDED: "undecided", BELOW_RACKET: "below_racket", STICKING: "sticking",
                RESTING: "resting"}
#: a cell two attractors share (at the tessellation's resolution): owned by neither
SHARED_CELL = -2


@dataclass(frozen=True)
class RecurrenceSettings:
    """The tessellation and the budgets of the recurrence (see the module docstring).

    cells_theta, cells_v: cells across the wrapped phase [0, 2 pi) and the velocities
    ``v_range`` (m/s; states outside fall in one cell of their own above or below).
    consecutive: impacts in a row in one attractor's cells that put a start in its basin.
    max_impacts: impacts a start is followed in the labelling pass before it is discovered
    anew. transient, window: impacts of the discovery before recording, and recorded.
    max_period, period_tolerance: the periods looked for and how closely they repeat (m/s,
    rad). same_orbit: two periodic orbits closer than this (m/s and rad) are one.
    sample: starts the first discovery follows. min_hop_s: section 3's sticking rule (0:
    exact sticking). lyapunov_impacts: impacts the exponent of a recurring orbit is measured
    over (after ``transient``). recurrence: impacts in a row in cells an orbit without a
    period had visited that make it recurrent (an attractor found), within
    ``recurrence_impacts``."""

    cells_theta: int = 200
    cells_v: int = 200
    v_range: tuple[float, float] = (0.0, 10.0)
    consecutive: int = 8
    max_impacts: int = 300
    transient: int = 1000
    window: int = 256
    max_period: int = 64
    period_tolerance: float = 1e-7
    same_orbit: float = 1e-5
    sample: int = 500
    min_hop_s: float = MIN_HOP_S
    lyapunov_impacts: int = 2000
    recurrence: int = 100
    recurrence_impacts: int = 20000

    def __post_init__(self) -> None:
        if self.window < 2 * self.max_period:
            raise ModelError("window must be at least 2 max_period")
        if not self.v_range[0] < self.v_range[1]:
            raise ModelError("v_range must be (low, high) with low < high")


@dataclass(frozen=True)
class Tessellation:
    """Cells of (wrapped theta, v): code = i_theta * (cells_v + 2) + i_v, with i_v 0 below
    ``v_range``, cells_v + 1 above it."""

    cells_theta: int
    cells_v: int
    v_low: float
    v_high: float

    @classmethod
    def of(cls, s: RecurrenceSettings) -> "Tessellation":
        return cls(s.cells_theta, s.cells_v, float(s.v_range[0]), float(s.v_range[1]))

    @property
    def size(self) -> int:
        return self.cells_theta * (self.cells_v + 2)

    @property
    def scales(self) -> tuple[float, float]:
        """Cells per radian of phase and per m/s of velocity."""
        return self.cells_theta / TWO_PI, self.cells_v / (self.v_high - self.v_low)

    def code(self, theta, v) -> np.ndarray:
        """The cell of each state (wrapped theta, v); ``model.compiled._cell`` repeats it."""
        theta_scale, v_scale = self.scales
        # a NaN phase (a ball that could not fly) in the first column, as the cast and the
        # clip put it, without the cast's warning
        column = np.nan_to_num(np.mod(theta, TWO_PI) * theta_scale, nan=0.0)
        i = np.clip(column.astype(np.int64), 0, self.cells_theta - 1)
        j = np.floor((np.asarray(v) - self.v_low) * v_scale)
        j = np.clip(np.nan_to_num(j, nan=-1.0, posinf=self.cells_v, neginf=-1.0), -1,
                    self.cells_v).astype(np.int64) + 1
        return i * (self.cells_v + 2) + j


@dataclass
class Attractor:
    """One attractor: ``kind`` periodic | chaotic | recurrent (bounded, no period, exponent
    not positive) | locked (exact sticking's periodic sticking orbit); for a periodic orbit its
    ``period`` (impacts), ``cycles`` (racket cycles per period), its points (wrapped theta,
    v) and ``multipliers`` (eigenvalues of F^p's Jacobian); for the others a sample of
    points; ``lyapunov``: largest exponent per impact (NaN where not measured);
    ``cells``: the tessellation's cells it occupies."""

    index: int
    kind: str
    period: int
    cycles: int
    theta: np.ndarray
    v: np.ndarray
    cells: np.ndarray
    multipliers: np.ndarray = field(default_factory=lambda: np.array([], complex))
    lyapunov: float = math.nan
    refined: bool = False

    @property
    def name(self) -> str:
        if self.kind == "periodic":
            cycles = f" ({_cycles(self.cycles)})" if self.cycles != self.period else ""
            return f"period-{self.period}{cycles}"
        if self.kind == "locked":
            return f"locked ({_cycles(self.cycles)})"
        return self.kind


def periodic_lyapunov(multipliers: np.ndarray, period: int) -> float:
    """The largest Lyapunov exponent per impact of a period-``period`` orbit from its
    multipliers (the eigenvalues of F^p's Jacobian): ln max |mu| / p (NaN without finite
    multipliers; -inf where the largest is 0)."""
    magnitudes = np.abs(np.asarray(multipliers))
    if magnitudes.size == 0 or not np.all(np.isfinite(magnitudes)) or period < 1:
        return math.nan
    largest = float(magnitudes.max())
    return math.log(largest) / period if largest > 0.0 else -math.inf


def _cycles(n: int) -> str:
    """'1 cycle', '3 cycles' (racket cycles)."""
    return f"{n} cycle{'s' if n != 1 else ''}"


@dataclass
class AttractorMap:
    """Every start's label (an attractor's index or a negative code, ``OTHER_LABELS``), the
    attractors, the impacts each start was followed for, and how many starts needed the
    second discovery."""

    labels: np.ndarray
    attractors: list[Attractor]
    impacts: np.ndarray
    rediscovered: int

    def name_of(self, label: int) -> str:
        return OTHER_LABELS[label] if label < 0 else self.attractors[label].name


# -- discovery ---------------------------------------------------------------------------------
@dataclass
class _Catalogue:
    """The attractors found so far and which attractor owns each cell."""

    params: ModelParams
    settings: RecurrenceSettings
    cells: Tessellation
    attractors: list[Attractor] = field(default_factory=list)
    owner: np.ndarray = field(init=False)
    #: the largest velocity after impact the discovery's orbits reached (m/s): above the
    #: tessellation's range the cells are one per phase column, too coarse to resolve an
    #: attractor there (``AttractorFinder.beyond_cells``)
    v_max_seen: float = -math.inf

    def __post_init__(self) -> None:
        self.owner = np.full(self.cells.size, -1, dtype=np.int64)

    def saw(self, v: np.ndarray | float) -> None:
        """Keep the largest finite velocity of ``v`` in ``v_max_seen``."""
        self.v_max_seen = _largest_finite(v, self.v_max_seen)

    def add(self, attractor: Attractor) -> int:
        attractor.index = len(self.attractors)
        self.attractors.append(attractor)
        mine = np.unique(attractor.cells)
        taken = self.owner[mine]
        self.owner[mine] = np.where(taken == -1, attractor.index, SHARED_CELL)
        return attractor.index

    def periodic_match(self, period: int, theta: float, v: float) -> int | None:
        tol = self.settings.same_orbit * 100.0  # the points are converged to period_tolerance
        for a in self.attractors:
            if a.kind == "periodic" and a.period == period and np.any(
                    (np.abs(a.v - v) < tol) & (np.abs(phase_difference(a.theta, theta)) < tol)):
                return a.index
        return None


def _largest_finite(v, top: float) -> float:
    """The largest of ``top`` and the finite values of ``v``."""
    finite = np.asarray(v)[np.isfinite(v)]
    return max(top, float(finite.max())) if finite.size else top


def _impact(impact_map: PassiveMap, state: State, settings: RecurrenceSettings):
    """One impact of wrapped states: (step, stuck), stuck where the hop is shorter than
    ``min_hop_s`` (NaN: the ball could not fly) or, with exact sticking, the chatter after
    the impact is complete (``model.chatter``)."""
    step = impact_map.step(state, wrap=True)
    stuck = ~(step.hop_s >= settings.min_hop_s)
    if settings.min_hop_s == 0.0:
        stuck |= impact_map.summable_chatter(step.state)
    return step, stuck


def _iterate(impact_map: PassiveMap, state: State, n: int, settings: RecurrenceSettings,
             record: bool):
    """n impacts of every state (wrapped); (final state, stuck mask, recorded v, theta,
    hops) with NaN rows from the impact a state stuck on."""
    count = state.theta.size
    alive = np.ones(count, dtype=bool)
    v_rec = np.full((count, n if record else 0), np.nan)
    th_rec = np.full_like(v_rec, np.nan)
    hop_rec = np.full_like(v_rec, np.nan)
    idx = np.arange(count)
    current = state
    final_theta, final_v = state.theta.copy(), state.v.copy()
    for k in range(n):
        if idx.size == 0:
            break
        step, stuck = _impact(impact_map, current, settings)
        current = step.state
        if record:
            v_rec[idx, k], th_rec[idx, k] = current.v, current.theta
            hop_rec[idx, k] = step.hop_phase
        if stuck.any():
            alive[idx[stuck]] = False
            keep = ~stuck
            idx, current = idx[keep], current.take(keep)
    final_theta[idx], final_v[idx] = current.theta, current.v
    return final_theta, final_v, ~alive, v_rec, th_rec, hop_rec


def _refine_periodic(params: ModelParams, v: np.ndarray, theta: np.ndarray, hops: np.ndarray,
                     period: int):
    """Newton on F^p(x) - x - (0, 2 pi m) from recorded points of a period-p orbit: (points
    theta (wrapped) and v of the refined orbit, cycles m, multipliers, converged)."""
    x = np.array([v[0], theta[0]], float)
    guess = np.asarray(hops[1:period + 1], float)
    cycles = int(round(float(np.sum(guess)) / TWO_PI))
    converged = False
    ev = None
    for _ in range(20):
        ev = evaluate_orbit(x, params, "racket_amplitude", cycles, guess)
        if not ev.finite:
            break
        step = np.linalg.solve(ev.monodromy - np.eye(2), -ev.residual)
        x = x + step
        guess = ev.hops
        if np.max(np.abs(step)) < 1e-13 * max(1.0, float(np.max(np.abs(x)))):
            converged = True
            break
    if ev is None or not ev.finite:
        return np.mod(theta[:period], TWO_PI), v[:period], cycles, np.array([], complex), False
    ev = evaluate_orbit(x, params, "racket_amplitude", cycles, guess)
    del converged  # the residual decides: Newton's last steps may stall at rounding level
    return (np.mod(ev.theta[:period], TWO_PI), ev.v[:period], cycles,
            np.linalg.eigvals(ev.monodromy), bool(np.max(np.abs(ev.residual)) < 1e-9))


def _least_period(theta: np.ndarray, v: np.ndarray, tolerance: float = 1e-8) -> int:
    """The least period of a refined orbit's p points (a divisor d of p whose shift maps the
    points onto themselves): a period-1 orbit near its flip is first taken for period 2, and
    Newton on F^2 converges to the period-1 orbit."""
    p = theta.size
    for d in range(1, p):
        if p % d == 0 and np.all(np.abs(np.roll(v, -d) - v) < tolerance) and np.all(
                np.abs(phase_difference(np.roll(theta, -d), theta)) < tolerance):
            return d
    return p


def _discover(cat: _Catalogue, impact_map: PassiveMap, theta, v, stick_label: int,
              follow: Callable = builtins.map,
              on_done: Callable[[int], object] | None = None) -> np.ndarray:
    """Discovery (module docstring, pass 1) of the states (theta, v): their labels (those
    that stick: ``stick_label``); the attractors found are added to the catalogue.
    ``follow``: the map over chunks of orbits without a period whose recurrence is followed
    (``_recurrence``: it reads the catalogue's cells only), e.g. an executor's of threads,
    as the compiled loop releases the GIL; the attractors they find are catalogued in the
    chunks' order, so the result is the same for any map. ``on_done(n)``: n more of the
    states are done (a progress bar's advance; all of them in the end)."""
    s = cat.settings
    done = on_done if on_done is not None else (lambda n: None)
    labels = np.full(np.size(theta), UNDECIDED, dtype=np.int64)
    if labels.size == 0:
        return labels
    # window by window: an orbit is done as soon as its last 2 max_period impacts repeat
    # with a period; the others go on, up to transient + window impacts in all
    open_ = np.arange(labels.size)
    th, vv = np.asarray(theta, float).ravel(), np.asarray(v, float).ravel()
    followed = 0
    while open_.size and followed < s.transient + s.window:
        last_th, last_v, stuck, v_rec, th_rec, hop_rec = _iterate(
            impact_map, impact_map.start(th[open_], vv[open_], wrap=True), s.window, s,
            record=True)
        followed += s.window
        cat.saw(v_rec)
        labels[open_[stuck]] = stick_label
        keep = ~stuck
        open_, v_rec, th_rec, hop_rec = open_[keep], v_rec[keep], th_rec[keep], hop_rec[keep]
        th[open_], vv[open_] = last_th[keep], last_v[keep]
        tail = slice(s.window - 2 * s.max_period, s.window)
        period = detect_period(v_rec[:, tail], th_rec[:, tail], s.max_period,
                               s.period_tolerance)
        for i in np.flatnonzero(period > 0):
            p = int(period[i])
            # the orbit's point with the smallest wrapped phase stands for it
            j = int(np.argmin(th_rec[i, -p:])) + s.window - p
            found = cat.periodic_match(p, th_rec[i, j], v_rec[i, j])
            while found is None:
                points_th, points_v, cycles, multipliers, refined = _refine_periodic(
                    cat.params, v_rec[i, -2 * p:], th_rec[i, -2 * p:], hop_rec[i, -2 * p:], p)
                least = _least_period(points_th, points_v, 1e-8 if refined else
                                      10 * s.period_tolerance)
                if least < p:  # near a flip a slowly converging orbit repeats every 2p first
                    p = least
                    found = cat.periodic_match(p, points_th[0], points_v[0])
                    continue
                found = cat.add(Attractor(-1, "periodic", p, cycles, points_th, points_v,
                                          cat.cells.code(points_th, points_v), multipliers,
                                          lyapunov=periodic_lyapunov(multipliers, p),
                                          refined=refined))
            labels[open_[i]] = found
        still = period == 0
        done(int(stuck.sum() + (~still).sum()))
        open_, v_rec, th_rec = open_[still], v_rec[still], th_rec[still]
    if open_.size == 0:
        return labels
    parts = [np.arange(c, min(c + RECURRENCE_CHUNK, open_.size))
             for c in range(0, open_.size, RECURRENCE_CHUNK)]
    followed = follow(lambda part: _recurrence(s, cat.cells, impact_map, th_rec[part],
                                               v_rec[part]), parts)
    for part, (recurred, visited, v_max, stuck) in zip(parts, followed):
        cat.saw(v_max)
        labels[open_[part[stuck]]] = stick_label  # stuck before it recurred: it sticks
        _add_recurrent(cat, open_[part[recurred]], visited[recurred], th_rec[part[recurred]],
                       v_rec[part[recurred]], labels)
        done(part.size)
    return labels


#: orbits whose recurrence is followed together (a boolean row of cells each)
RECURRENCE_CHUNK = 256


def _recurrence(s: RecurrenceSettings, cells: Tessellation, impact_map: PassiveMap, th_rec,
                v_rec):
    """Orbits without a period, from their last recorded state on: each followed until
    ``recurrence`` impacts in a row land in cells it had visited (Datseris & Wagemakers'
    criterion for an attractor found), for at most ``recurrence_impacts``, or until it
    sticks. (recurred mask, visited cells per orbit as a boolean row, the largest finite
    velocity reached, the mask of the orbits that stuck before they recurred)."""
    m = th_rec.shape[0]
    visited = np.zeros((m, cells.size), dtype=bool)
    rows = np.arange(m)
    visited[np.repeat(rows, th_rec.shape[1]), cells.code(th_rec, v_rec).ravel()] = True
    streak = np.zeros(m, dtype=np.int64)
    recurred = np.zeros(m, dtype=bool)
    stuck_rows = np.zeros(m, dtype=bool)
    idx = rows.copy()
    state = impact_map.start(th_rec[:, -1], v_rec[:, -1], wrap=True)
    if impact_map.compiled_hops and s.min_hop_s > 0.0:  # the loop below, compiled
        from ..model.compiled import recurrence_arrays

        theta_scale, v_scale = cells.scales
        cos_th, sin_th = state.extra
        v_max = recurrence_arrays(
            state.theta, state.v, cos_th, sin_th, impact_map.params, min_hop_s=s.min_hop_s,
            cells=(cells.cells_theta, theta_scale, cells.cells_v, cells.v_low, v_scale),
            recurrence=s.recurrence, max_impacts=s.recurrence_impacts, visited=visited,
            recurred=recurred, stuck=stuck_rows, max_steps=MAX_SAFE_STEPS)
        return recurred, visited, v_max, stuck_rows
    v_max = -math.inf
    for _ in range(s.recurrence_impacts):
        if idx.size == 0:
            break
        step, stuck = _impact(impact_map, state, s)
        state = step.state
        v_max = _largest_finite(state.v, v_max)
        code = cells.code(state.theta, state.v)
        new = ~visited[idx, code]
        visited[idx, code] = True
        streak = np.where(new, 0, streak + 1)
        done = streak >= s.recurrence
        recurred[idx[done]] = True
        stuck_rows[idx[stuck & ~done]] = True
        keep = ~(done | stuck)
        idx, state, streak = idx[keep], state.take(keep), streak[keep]
    return recurred, visited, v_max, stuck_rows


def _add_recurrent(cat: _Catalogue, which, visited, theta, v, labels) -> None:
    """Orbits that recurred without a period: one attractor per connected set of the cells
    they visited (the cells of one orbit are connected), a known one where its cells are
    already one attractor's."""
    if len(which) == 0:
        return
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    orbit, cell = np.nonzero(visited)
    used, inverse = np.unique(cell, return_inverse=True)
    first = np.full(visited.shape[0], -1, dtype=np.int64)
    first[orbit[::-1]] = inverse[::-1]  # each orbit's first cell (lowest code)
    graph = coo_matrix((np.ones(orbit.size), (first[orbit], inverse)),
                       shape=(used.size, used.size))
    _, component = connected_components(graph, directed=False)
    orbit_component = component[first]
    for c in np.unique(orbit_component):
        members = np.flatnonzero(orbit_component == c)
        cells = used[component == c]
        owners = cat.owner[cells]
        known = owners[owners >= 0]
        near = _near_periodic(cat, theta[members, -1], v[members, -1])
        if near is not None:  # converging, slowly, onto a known orbit (near a bifurcation)
            index = near
        elif known.size and np.all(known == known[0]):
            index = int(known[0])
        else:
            pts_th, pts_v = theta[members].ravel(), v[members].ravel()
            pick = np.linspace(0, pts_th.size - 1, min(pts_th.size, 2000)).astype(int)
            lyap = _lyapunov(cat, float(pts_th[-1]), float(pts_v[-1]))
            kind = "chaotic" if lyap > 0.0 else "recurrent"
            index = cat.add(Attractor(-1, kind, 0, 0, pts_th[pick], pts_v[pick], cells,
                                      lyapunov=lyap))
        labels[np.asarray(which)[members]] = index


def _near_periodic(cat: _Catalogue, theta: np.ndarray, v: np.ndarray,
                   distance: float = 1e-3) -> int | None:
    """The periodic attractor every one of these states is within ``distance`` (m/s and rad)
    of a point of, if there is one."""
    for a in cat.attractors:
        if a.kind != "periodic":
            continue
        close = ((np.abs(v[:, None] - a.v[None, :]) < distance)
                 & (np.abs(phase_difference(theta[:, None], a.theta[None, :])) < distance))
        if np.all(close.any(axis=1)):
            return a.index
    return None


def _lyapunov(cat: _Catalogue, theta: float, v: float) -> float:
    """The largest Lyapunov exponent per impact from a point of a recurring orbit
    (``bifurcation.iterate_sweep``, the project's one routine)."""
    s = cat.settings
    settings = SweepSettings(transient_impacts=0, measured_impacts=s.lyapunov_impacts,
                             recorded_impacts=2 * s.max_period, max_period=s.max_period,
                             min_hop_s=s.min_hop_s)
    orbits = iterate_sweep([theta], [v], sweep_parameters(cat.params, "alpha",
                                                          [cat.params.alpha]), settings)
    return float(orbits.lyapunov[0])


# -- labelling ---------------------------------------------------------------------------------
def _label(cat: _Catalogue, impact_map: PassiveMap, theta, v, stick_label: int):
    """Labelling (module docstring, pass 2): (labels, impacts followed, final theta, v) of
    the states; UNDECIDED where ``max_impacts`` was not enough."""
    s = cat.settings
    n = np.size(theta)
    labels = np.full(n, UNDECIDED, dtype=np.int64)
    impacts = np.full(n, s.max_impacts, dtype=np.int64)
    final_th, final_v = np.array(theta, float), np.array(v, float)
    idx = np.arange(n)
    state = impact_map.start(theta, v, wrap=True)
    run_owner = np.full(n, -1, dtype=np.int64)
    run = np.zeros(n, dtype=np.int64)
    for k in range(1, s.max_impacts + 1):
        if idx.size == 0:
            break
        step, stuck = _impact(impact_map, state, s)
        state = step.state
        owner = cat.owner[cat.cells.code(state.theta, state.v)]
        same = (owner >= 0) & (owner == run_owner)
        run = np.where(same, run + 1, (owner >= 0).astype(np.int64))
        run_owner = owner
        settled = stuck | (run >= s.consecutive)
        if settled.any():
            done = idx[settled]
            labels[done] = np.where(stuck[settled], stick_label, owner[settled])
            impacts[done] = k
            keep = ~settled
            idx, state, run, run_owner = idx[keep], state.take(keep), run[keep], run_owner[keep]
    final_th[idx], final_v[idx] = state.theta, state.v
    return labels, impacts, final_th, final_v


def label_tile(args):
    """One task of :meth:`AttractorFinder.label`: (catalogue, map, theta0, v0, stick label)
    -> ``_label``'s (labels, impacts, final theta, final v); module-level, so that worker
    processes can receive it."""
    catalogue, impact_map, theta0, v0, stick = args
    return _label(catalogue, impact_map, theta0, v0, stick)


def _stick_label(cat: _Catalogue, impact_map: PassiveMap) -> int:
    """The label of a start that sticks: ``STICKING`` under section 3's rule; with exact
    sticking every orbit that sticks is released in one state (``model.chatter``), so it
    takes that released ball's attractor: the locked orbit (it sticks again), rest (Gamma <=
    1), or the attractor its first impact after the release reaches (discovered here)."""
    s, p = cat.settings, cat.params
    if s.min_hop_s > 0.0:
        return STICKING
    fate = release_fate(p, s.transient + s.window, 1e-9, None)
    if fate.kind == "resting":
        return RESTING
    if fate.kind == "locked":
        return cat.add(Attractor(-1, "locked", 0, fate.cycles, np.array([]), np.array([]),
                                 np.array([], np.int64), lyapunov=-math.inf))
    start = release_phase(0.0, p)
    orbit = iterate_exact_orbit(start, float(p.racket_velocity(start)), p, 1,
                                start_released=True)
    impacts = orbit.rows("impact")
    if impacts.size == 0:
        return UNDECIDED
    k = int(impacts[0])
    return int(_discover(cat, impact_map, np.array([orbit.theta[k]]), np.array([orbit.v[k]]),
                         UNDECIDED)[0])


class AttractorFinder:
    """The recurrence at one parameter point, its catalogue of attractors kept between
    calls: :meth:`discover` on a sample first, then :meth:`label` any starts (a grid, the
    uncertainty exponent's perturbed points), each with the same attractor indices.

    Parameters
    ----------
    params : ModelParams
        The model (eqs. 5, 6).
    settings : RecurrenceSettings
        Tessellation and budgets.
    """

    def __init__(self, params: ModelParams, settings: RecurrenceSettings = RecurrenceSettings()):
        self.params, self.settings = params, settings
        # the first-impact solves compiled where numba is installed (the same bits): the
        # discovery follows a few hundred orbits for thousands of impacts, where numpy's
        # cost is its calls (at a chaotic point 20-40x the solve's arithmetic)
        self.map = replace(PassiveMap.of(params, require_fixed_point=False),
                           compiled_hops=compiled_kernel_available())
        self.catalogue = _Catalogue(params, settings, Tessellation.of(settings))
        self.stick = _stick_label(self.catalogue, self.map)
        self.rediscovered = 0

    @property
    def attractors(self) -> list[Attractor]:
        return self.catalogue.attractors

    def beyond_cells(self) -> float | None:
        """The largest velocity the discovery's orbits reached more than one cell above the
        tessellation's ``v_range`` (m/s), where its cells are one per phase column and
        cannot resolve an attractor (alpha 0.9: a chaotic attractor up to 40 m/s; with
        v_range [0, 12] no orbit recurs and 22 % of the starts are left undecided); None
        where every orbit stayed inside it or within a cell of its top."""
        seen, cells = self.catalogue.v_max_seen, self.catalogue.cells
        # within one cell's height of the range's top, the coarse cells above are harmless
        # (alpha 0.85: 12.04 m/s reached with the range [0, 12], no start left undecided)
        cell = (cells.v_high - cells.v_low) / cells.cells_v
        return seen if seen > cells.v_high + cell else None

    def _flat(self, theta0, v0):
        theta0, v0 = np.broadcast_arrays(np.asarray(theta0, float), np.asarray(v0, float))
        flies = np.asarray(self.map.launches(self.map.start(theta0.ravel(), v0.ravel())),
                           dtype=bool)
        return theta0.shape, theta0.ravel(), v0.ravel(), flies

    def discover(self, theta0, v0, *, follow: Callable = builtins.map) -> None:
        """Discovery (pass 1) from the starts that can leave the racket; ``follow`` as for
        :meth:`label`."""
        _, theta0, v0, flies = self._flat(theta0, v0)
        _discover(self.catalogue, self.map, theta0[flies], v0[flies], self.stick, follow)

    def label(self, theta0, v0, *, map: Callable = builtins.map, workers: int = 1,
              tile_points: int = DEFAULT_TILE_POINTS,
              follow: Callable = builtins.map,
              progress: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """(labels, impacts followed) of starts (arrays broadcast), in their shape. The
        labelling pass runs in tiles through ``map`` (an executor's: worker processes),
        the discovery of what it leaves here, so that the catalogue is one, its orbits'
        recurrences through ``follow`` (an executor's of threads: the compiled loop releases
        the GIL; ``_discover``); the result is the same for any ``map``, ``workers``,
        ``tile_points`` and ``follow``. ``progress`` (``start(total, description)``,
        ``advance(n)``, e.g. a run's progress bar) hears of both passes."""
        shape, theta0, v0, flies = self._flat(theta0, v0)
        s = self.settings
        labels = np.full(theta0.size, BELOW_RACKET, dtype=np.int64)
        impacts = np.zeros(theta0.size, dtype=np.int64)
        idx = np.flatnonzero(flies)
        got = np.empty(idx.size, dtype=np.int64)
        used = np.empty(idx.size, dtype=np.int64)
        th, vv = np.empty(idx.size), np.empty(idx.size)
        tiles = tile_slices(idx.size, tile_points, workers)
        tasks = ((self.catalogue, self.map, theta0[idx[t]], v0[idx[t]], self.stick)
                 for t in tiles)
        if progress is not None:
            progress.start(idx.size, "attractors: labelling the starts")
        for t, part in zip(tiles, map(label_tile, tasks)):
            got[t], used[t], th[t], vv[t] = part
            if progress is not None:
                progress.advance(got[t].size)
        labels[idx], impacts[idx] = got, used
        left = np.flatnonzero(got == UNDECIDED)
        if left.size:
            if progress is not None:
                progress.start(left.size, "attractors: following the undecided starts further")
            labels[idx[left]] = _discover(self.catalogue, self.map, th[left], vv[left],
                                          self.stick, follow,
                                          None if progress is None else progress.advance)
            impacts[idx[left]] += s.transient + s.window
            self.rediscovered += int(left.size)
        return labels.reshape(shape), impacts.reshape(shape)


def find_attractors(theta0, v0, params: ModelParams,
                    settings: RecurrenceSettings = RecurrenceSettings(),
                    rng: np.random.Generator | None = None) -> AttractorMap:
    """Every start (theta0, v0) (the ball leaving the racket at phase theta0, rad, with v0,
    m/s; arrays broadcast) labelled by the attractor it reaches (module docstring): discovery
    on ``settings.sample`` starts drawn from them, then the labelling of all.

    Parameters
    ----------
    theta0, v0 : array_like
        The starts.
    params : ModelParams
        The model (eqs. 5, 6).
    settings : RecurrenceSettings
        Tessellation and budgets.
    rng : numpy.random.Generator, optional
        Draws the discovery's sample (default: seeded 0, so a call is reproducible).

    Returns
    -------
    AttractorMap
        Labels in the starts' shape, the attractors, impacts followed per start.
    """
    finder = AttractorFinder(params, settings)
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, float), np.asarray(v0, float))
    rng = np.random.default_rng(0) if rng is None else rng
    pick = rng.choice(theta0.size, size=min(settings.sample, theta0.size), replace=False)
    finder.discover(theta0.ravel()[pick], v0.ravel()[pick])
    labels, impacts = finder.label(theta0, v0)
    return AttractorMap(labels, finder.attractors, impacts, finder.rediscovered)


# -- basin measures ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Fraction:
    """A label's share of the starts with its 95 % Wilson interval."""

    label: int
    count: int
    fraction: float
    low: float
    high: float


def basin_fractions(labels: np.ndarray, z: float = 1.959963984540054) -> list[Fraction]:
    """Each label's fraction of the starts, with its Wilson score interval (the starts as a
    sample of the region: a binomial proportion); sorted by label."""
    flat = np.asarray(labels).ravel()
    n = flat.size
    out = []
    for label, count in zip(*np.unique(flat, return_counts=True)):
        p = count / n
        centre = (p + z * z / (2 * n)) / (1 + z * z / n)
        half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        out.append(Fraction(int(label), int(count), float(p), max(0.0, centre - half),
                            min(1.0, centre + half)))
    return out
