"""Classification of initial conditions for the basin of attraction (section 3, Fig. 4).

Each initial condition (theta0, v0) -- the ball leaves the racket at phase theta0 (rad) with
velocity v0 (m/s) -- is iterated with the map (eqs. 5, 6) until one of section 3's stopping
conditions occurs:

* ``below_racket``: v0 is not above the racket's velocity at theta0 (``can_fly`` false at
  k = 0), so the ball cannot leave the racket; 0 iterations.
* ``sticking``: a hop (time between two impacts) lasts less than ``min_hop_s``.
  A ball that cannot leave the racket after an impact (grazing, possible only for alpha = 0)
  is sticking too.
* ``period1``: after an impact both ``|v - v~| < tolerance`` (m/s) and
  ``|wrap(theta) - theta~| < tolerance`` (rad, the wrapped phase difference).
* ``undecided``: none of these within ``max_iterations`` impacts.

With ``min_hop_s`` 0 (exact sticking, ``model.chatter``) a point sticks where a complete
chatter's tail is summable instead; since every orbit that sticks is released in the same
state, it takes the released ball's one fate: ``locked`` (the periodic sticking solution,
``Classification.locked_cycles`` racket cycles), ``resting`` (Gamma <= 1), or ``period1`` /
``undecided`` when the released ball goes there. The compiled kernel does not implement it:
the numpy code runs whatever ``kernel`` says.

The iteration count is the number of impacts computed until the point was classified
(1..max_iterations for period1 / sticking, max_iterations for undecided, 0 for below_racket).
The initial state itself is NOT compared with the fixed point: the first check is after
impact 1, so even the fixed point itself is ``period1`` after 1 iteration. At each impact
the sticking test comes first (a hop that short is never near the fixed point anyway).

All points of a batch advance together: one vectorised first-impact solve
(``impact.first_impact_phase``) per impact on the still-active subset; settled points are
dropped. Phases are kept wrapped in [0, 2 pi). The result of a point does not depend on
which other points share its batch, so ``classify_grid`` gives identical results for any
tile size and number of worker processes.
"""

from __future__ import annotations

import builtins
import functools
import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Literal

import numpy as np

from ..model.chatter import release_fate
from ..model.impact import MAX_SAFE_STEPS
from ..model.linear import stability
from ..model.maps import ClassifySettings, ImpactMap, PassiveMap
from ..model.params import FixedPoint, ModelError, ModelParams

PERIOD1, STICKING, BELOW_RACKET, UNDECIDED, LOCKED, RESTING = 0, 1, 2, 3, 4, 5
#: outcome names indexed by their integer code (section 3's, with ``min_hop_s`` > 0)
OUTCOMES = ("period1", "sticking", "below_racket", "undecided")
#: with exact sticking (``min_hop_s`` 0: ``model.chatter``) "sticking" never occurs; an orbit
#: that sticks is "locked" (its release repeats: periodic, superstable) or "resting" (Gamma
#: <= 1: never released), or takes the fate of the released ball (period1, undecided)
EXACT_OUTCOMES = OUTCOMES + ("locked", "resting")


def outcome_names(settings: "ClassifySettings") -> tuple[str, ...]:
    """The outcomes a classification with ``settings`` can give: ``OUTCOMES``, or
    ``EXACT_OUTCOMES`` with exact sticking (min_hop_s 0)."""
    return EXACT_OUTCOMES if settings.min_hop_s == 0.0 else OUTCOMES

TWO_PI = 2.0 * math.pi
#: default number of grid points per tile (memory per tile: a few tens of MB)
DEFAULT_TILE_POINTS = 1 << 15


@dataclass(frozen=True)
class Classification:
    """Outcome codes (index into ``EXACT_OUTCOMES``, int8) and iteration counts (int16);
    ``locked_cycles``: with exact sticking, the period in racket cycles of the locked orbit
    that every orbit that sticks ends on (0: none at these parameters)."""

    outcome: np.ndarray
    iterations: np.ndarray
    locked_cycles: int = 0

    def names(self) -> np.ndarray:
        return np.asarray(EXACT_OUTCOMES, dtype=object)[self.outcome]


def compiled_kernel_available() -> bool:
    """True when the compiled kernel (``model.compiled``, numba) can be used: the
    environment variable ``BOUNCE_KERNEL`` is not ``numpy``, numba is installed and either
    the kernel's machine code loads without numba (``model.native``) or the kernel's module
    imports (numba may refuse, e.g. with no writable cache directory: then the numpy kernel
    runs, with the same results)."""
    from ..model import native

    if native.kernel_choice() == "numpy" or not native.numba_installed():
        return False
    return native.classifier() is not None or _compiled_module_imports()


@functools.lru_cache(maxsize=None)
def _compiled_module_imports() -> bool:
    try:
        from ..model import compiled  # noqa: F401
    except Exception:
        return False
    return True


def load_compiled_kernel() -> None:
    """Load the compiled kernel, so that later calls start at once: its machine code without
    numba where it was saved (``model.native``: about 0.05 s), else numba and the kernel
    from numba's cache (about 0.4 s; the first time ever, compiled: a few seconds), and
    then its machine code saved for the next run (about a second, once)."""
    if not compiled_kernel_available():
        return
    from ..model import native

    if native.classifier() is not None:
        return
    from ..model.compiled import load

    load()
    native.build_classifier()


def passive_map(params: ModelParams, *, require_fixed_point: bool = True) -> PassiveMap:
    """The passive map the classifier iterates: eqs. 7, 8's fixed point as target where it
    attracts (linearly stable, eq. 10, by more than rounding: ``linear.is_stable``). Where
    it is unstable no orbit stays at it, and a start that passes within the tolerance of it
    by chance has reached no attractor: the target is NaN (no start is ``period1``). Where
    there is no fixed point: NoFixedPointError, unless ``require_fixed_point`` is False (a
    NaN target)."""
    impact_map = PassiveMap.of(params, require_fixed_point=require_fixed_point)
    if math.isnan(impact_map.target.v_m_s) or stability(params).stable:
        return impact_map
    return PassiveMap(params)


def classify_batch(theta0, v0, params: ModelParams,
                   settings: ClassifySettings = ClassifySettings(), *,
                   require_fixed_point: bool = True,
                   kernel: Literal["auto", "numpy", "compiled"] = "auto") -> Classification:
    """Classify initial conditions (arrays broadcast) of the passive map in one batch.

    Returns a ``Classification`` with the broadcast shape. See the module docstring for the
    outcomes and the meaning of the iteration count. Without a period-1 fixed point (eq. 8)
    this raises NoFixedPointError, unless ``require_fixed_point`` is False: then no point is
    ``period1`` and the others are decided by the same iteration (parameter sweeps).

    ``kernel``: "numpy" is ``classify_states``'s loop; "compiled" the same arithmetic
    compiled with numba (``model.compiled``: identical outcomes and iteration counts, about
    3x faster per core); "auto" the compiled one when ``compiled_kernel_available()``.
    """
    return classify_states(passive_map(params, require_fixed_point=require_fixed_point),
                           theta0, v0, settings, kernel=kernel)


def classify_states(impact_map: ImpactMap, theta0, v0,
                    settings: ClassifySettings = ClassifySettings(), *,
                    kernel: Literal["auto", "numpy", "compiled"] = "auto") -> Classification:
    """Section 3's classification of initial conditions (arrays broadcast) of any map that
    implements the step protocol (``model.maps.ImpactMap``: the passive map, the
    controlled one of ``model.control``), in one vectorised batch: the one loop of the
    module docstring. ``kernel`` as for ``classify_batch``: the compiled kernel runs where
    the map has one (``has_compiled_kernel``) and exact sticking is not asked for."""
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, dtype=float), np.asarray(v0, dtype=float))
    shape = theta0.shape
    theta0, v0 = theta0.ravel(), v0.ravel()
    exact = settings.min_hop_s == 0.0  # exact sticking: the numpy kernel, whatever ``kernel``
    if not exact and has_compiled_kernel(impact_map) and (
            kernel == "compiled" or (kernel == "auto" and compiled_kernel_available())):
        codes, counts = impact_map.compiled_classification(  # type: ignore[attr-defined]
            theta0, v0, settings, MAX_SAFE_STEPS)
        return Classification(codes.reshape(shape), counts.reshape(shape))
    tol = settings.tolerance
    min_hop = settings.min_hop_s
    stick_code, stick_iterations, locked_cycles = STICKING, None, 0
    if exact:
        if not isinstance(impact_map, PassiveMap):
            raise ModelError("exact sticking (min_hop_s 0) is implemented for the passive "
                             "map only; give a shortest hop > 0")
        stick_code, stick_iterations, locked_cycles = _exact_sticking_fate(
            impact_map.params, settings, impact_map.target)

    outcome = np.full(theta0.shape, UNDECIDED, dtype=np.int8)
    iterations = np.full(theta0.shape, settings.max_iterations, dtype=np.int16)

    flies = impact_map.launches(impact_map.start(theta0, v0))
    outcome[~flies] = BELOW_RACKET
    iterations[~flies] = 0

    idx = np.flatnonzero(flies)
    state = impact_map.start(theta0[idx], v0[idx], wrap=True)
    for k in range(1, settings.max_iterations + 1):
        if idx.size == 0:
            break
        step = impact_map.step(state, wrap=True)
        state = step.state
        # NaN hop (cannot leave the racket) compares False: sticking
        sticking = ~(step.hop_s >= min_hop)
        if exact:  # sticks where a complete chatter's tail is summable (``model.chatter``)
            sticking |= impact_map.summable_chatter(state)  # type: ignore[attr-defined]
        period1 = impact_map.near_fixed_point(state, tol) & ~sticking
        settled = sticking | period1
        if settled.any():
            done = idx[settled]
            outcome[done] = np.where(sticking[settled], stick_code, PERIOD1)
            iterations[done] = (k if stick_iterations is None else
                                np.where(sticking[settled], stick_iterations(k), k))
            keep = ~settled
            idx, state = idx[keep], state.take(keep)
    return Classification(outcome.reshape(shape), iterations.reshape(shape), locked_cycles)


def _exact_sticking_fate(params: ModelParams, settings: ClassifySettings, fp: FixedPoint):
    """With exact sticking (min_hop_s 0): every orbit that sticks is released in the same
    state, so it takes the one fate of the released ball (``chatter.release_fate``): locked
    (its period in racket cycles), resting, or, when the released ball reaches the fixed point
    or nothing within ``max_iterations``, period1 (iterations: the impacts to the stick plus
    the released ball's) or undecided. Returns (outcome code of a sticking orbit, its
    iterations as a function of the impact k at which it stuck, locked period in cycles)."""
    fate = release_fate(params, settings.max_iterations, settings.tolerance,
                        None if math.isnan(fp.v_m_s) else fp)
    code = {"locked": LOCKED, "resting": RESTING, "period1": PERIOD1,
            "undecided": UNDECIDED}[fate.kind]
    limit = settings.max_iterations

    def iterations(k: int) -> int:
        if fate.kind == "period1":
            return min(k + fate.impacts, limit)
        return limit if fate.kind == "undecided" else k

    return code, iterations, fate.cycles if fate.kind == "locked" else 0


def has_compiled_kernel(impact_map: ImpactMap) -> bool:
    """The map has a compiled classification (``model.compiled``; the protocol's optional
    ``compiled_kernel`` and ``compiled_classification``)."""
    return bool(getattr(impact_map, "compiled_kernel", False))


def classify_tile(args):
    """One task of ``classify_grid``: (theta0, v0, impact_map, settings, kernel) -> (outcome,
    iterations, locked cycles); a module-level function, so that worker processes can
    receive it."""
    theta0, v0, impact_map, settings, kernel = args
    result = classify_states(impact_map, theta0, v0, settings, kernel=kernel)
    return result.outcome, result.iterations, result.locked_cycles


def classify_grid(
    theta0,
    v0,
    params: ModelParams | ImpactMap,
    settings: ClassifySettings = ClassifySettings(),
    *,
    map: Callable[[Callable[[Any], Any], Iterable[Any]], Iterator[Any]] = builtins.map,
    workers: int = 1,
    tile_points: int = DEFAULT_TILE_POINTS,
    on_tile_done: Callable[[int], None] | None = None,
    kernel: Literal["auto", "numpy", "compiled"] = "auto",
) -> Classification:
    """``classify_states`` for large arrays: cut into tiles of at most ``tile_points``
    points, each classified by ``map(classify_tile, tiles)`` (any ``map``-like callable that
    yields results in task order: the built-in ``map`` in this process, or an executor's
    ``map`` running tiles on ``workers`` processes; the engine starts no processes itself).

    ``params``: the passive map's parameters, or any map of the step protocol
    (``model.maps.ImpactMap``: the controlled map of ``model.control``).
    Tiles interleave the points (tile i holds points i, i + n, i + 2n, ... of the flattened
    arrays), so every tile gets the same mix of cheap and expensive initial conditions and
    the workers stay balanced; the number of tiles is a multiple of ``workers``.
    ``on_tile_done(n_points)`` is called once per finished tile with the number of points in
    it (for a progress bar). ``kernel`` as for ``classify_batch``. Results are identical for
    any ``map``, ``workers``, ``tile_points`` and ``kernel``.
    """
    impact_map = passive_map(params) if isinstance(params, ModelParams) else params
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, dtype=float), np.asarray(v0, dtype=float))
    shape = theta0.shape
    theta0, v0 = theta0.ravel(), v0.ravel()
    tiles = tile_slices(theta0.size, tile_points, workers)
    outcome = np.empty(theta0.shape, dtype=np.int8)
    iterations = np.empty(theta0.shape, dtype=np.int16)
    # copies: contiguous arrays for a worker (and small pickles); made as tiles are sent
    tasks = ((theta0[t].copy(), v0[t].copy(), impact_map, settings, kernel) for t in tiles)
    locked_cycles = 0  # the same in every tile: one release per parameter point
    for tile, (tile_outcome, tile_iterations, tile_cycles) in zip(
            tiles, map(classify_tile, tasks)):
        outcome[tile], iterations[tile] = tile_outcome, tile_iterations
        locked_cycles = tile_cycles
        if on_tile_done is not None:
            on_tile_done(tile_outcome.size)
    return Classification(outcome.reshape(shape), iterations.reshape(shape), locked_cycles)


def tile_slices(size: int, tile_points: int, workers: int = 1) -> list[slice]:
    """Interleaved tiles [slice(i, None, n) for i < n] covering range(size), each of at most
    ``tile_points`` points; n is rounded up to a multiple of ``workers``."""
    if tile_points < 1:
        raise ValueError("tile_points must be >= 1")
    n = max(1, -(-size // tile_points))
    if workers > 1:
        n = workers * -(-n // workers)
    n = min(n, max(size, 1))
    return [slice(i, None, n) for i in range(n)]
