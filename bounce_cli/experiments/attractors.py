"""``bounce attractors``: every start of a basin named by the attractor it reaches.

The Fig. 4 grid (or any configured region) labelled by recurrence (``analysis.attractors``):
the coexisting attractors (periodic orbits with their multipliers, chaotic attractors with
their Lyapunov exponent, exact sticking's locked orbit), each one's share of the region with
its interval, the basin entropy and boundary basin entropy (Daza et al. 2016) and the
uncertainty exponent of the boundaries (``analysis.basin_measures``), and the shares
continued over a racket parameter (Gamma by default) as a stacked plot, with eq. 8's
existence and eq. 14's flip of the period-1 orbit marked. Section 3's three classes are the
same result seen coarser: ``paper_class`` in ``basin.csv``.
"""

from __future__ import annotations

import itertools
import math
from typing import Any, Callable, Literal

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..analysis.attractors import (
    OTHER_LABELS,
    UNDECIDED,
    Attractor,
    AttractorFinder,
    RecurrenceSettings,
    basin_fractions,
    find_attractors,
)
from ..analysis.basin_measures import basin_entropy, uncertainty_exponent
from ..analysis.bifurcation import (SWEEPABLE, column_parameter, parameter_column,
                                    parameter_point, period1_thresholds)
from ..model.params import MIN_HOP_S, phase_difference
from ..runtime.config import ExperimentConfig, ModelBlock, StrictModel
from .base import Experiment, ExperimentResult, RunOptions
from ..runtime import parallel
from .basin import POOL_MIN_POINTS, GridBlock
from .plotting import caption_figures, cell_extent, publication_style


class RecurrenceBlock(StrictModel):
    """The tessellation of (theta mod 2 pi, v) and the recurrence's budgets."""

    cells_theta: int = Field(200, ge=4, le=5000, description="cells across the phase")
    cells_v: int = Field(200, ge=4, le=5000, description="cells across v_range_m_s")
    v_range_m_s: tuple[float, float] = Field((0.0, 12.0), description="velocities the cells "
                                             "cover, m/s (beyond: one cell each side)")
    consecutive: int = Field(8, ge=1, le=1000, description="impacts in a row in one "
                             "attractor's cells that put a start in its basin")
    max_impacts: int = Field(300, ge=1, le=100_000, description="impacts a start is followed "
                             "before it is discovered anew")
    transient: int = Field(1000, ge=0, le=1_000_000)
    window: int = Field(256, ge=4, le=100_000, description="impacts recorded after the "
                        "transient (>= 2 max_period)")
    max_period: int = Field(64, ge=1, le=10_000)
    period_tolerance: float = Field(1e-7, gt=0.0, description="m/s and rad")
    sample: int = Field(500, ge=1, le=1_000_000, description="starts the first discovery "
                        "follows")
    recurrence: int = Field(100, ge=1, description="impacts in a row in visited cells that "
                            "make an orbit without a period recurrent")
    recurrence_impacts: int = Field(20000, ge=1, le=10_000_000)
    min_hop_s: float = Field(MIN_HOP_S, ge=0.0, description="section 3's sticking rule, s (0: "
                             "exact sticking, model.chatter)")

    @model_validator(mode="after")
    def _checks(self):
        if self.window < 2 * self.max_period:
            raise ValueError("window must be at least 2 max_period")
        if not self.v_range_m_s[0] < self.v_range_m_s[1]:
            raise ValueError("v_range_m_s must be [low, high] with low < high")
        return self

    def settings(self) -> RecurrenceSettings:
        return RecurrenceSettings(
            cells_theta=self.cells_theta, cells_v=self.cells_v, v_range=self.v_range_m_s,
            consecutive=self.consecutive, max_impacts=self.max_impacts,
            transient=self.transient, window=self.window, max_period=self.max_period,
            period_tolerance=self.period_tolerance, sample=self.sample,
            min_hop_s=self.min_hop_s, recurrence=self.recurrence,
            recurrence_impacts=self.recurrence_impacts)


class MeasuresBlock(StrictModel):
    """Basin entropy over boxes of ``box`` x ``box`` grid points; the uncertainty exponent
    from ``samples`` random starts per eps (fractions of the region's spans)."""

    box: int = Field(5, ge=1, le=1000)
    eps: list[float] = Field(default_factory=lambda: [0.002, 0.004, 0.008, 0.016, 0.032])
    samples: int = Field(1000, ge=10, le=1_000_000)
    seed: int = Field(0, ge=0)

    @model_validator(mode="after")
    def _eps(self):
        if len(self.eps) < 2 or any(not 0.0 < e < 1.0 for e in self.eps):
            raise ValueError("eps: at least two values in (0, 1)")
        return self


class ContinuationBlock(StrictModel):
    """The shares of the attractors continued over a racket parameter (``values: {start,
    stop, num}``, linspace) on a coarser grid; ``num: 0`` for none."""

    parameter: Literal["gamma", "racket_amplitude", "racket_period"] = "gamma"
    start: float = 1.40
    stop: float = 1.80
    num: int = Field(17, ge=0, le=1000)

    @model_validator(mode="after")
    def _range(self):
        if self.num > 1 and not self.stop > self.start:
            raise ValueError("stop must be greater than start")
        return self
    grid: GridBlock = GridBlock.model_validate({
        "theta0_deg": {"start": 0.0, "stop": 360.0, "num": 90},
        "v0_m_s": {"start": 0.0, "stop": 10.0, "num": 90}})


class AttractorsConfig(ExperimentConfig):
    model: ModelBlock = ModelBlock()
    grid: GridBlock = GridBlock()
    recurrence: RecurrenceBlock = RecurrenceBlock()
    measures: MeasuresBlock = MeasuresBlock()
    continuation: ContinuationBlock = ContinuationBlock()
    max_points: int = Field(4_000_000, ge=1, description="largest grid accepted")

    @model_validator(mode="after")
    def _size(self):
        """The grid, and the continuation's grid at all its values, within max_points (a
        guard against runs of hours), in a message that names the keys to change."""
        th, v = self.grid.theta0_deg.num, self.grid.v0_m_s.num
        if th * v > self.max_points:
            raise ValueError(
                f"grid.theta0_deg.num x grid.v0_m_s.num = {th} x {v} = {th * v:,} starts, "
                f"more than max_points = {self.max_points:,}; reduce the grid or raise "
                "max_points")
        c = self.continuation
        th, v = c.grid.theta0_deg.num, c.grid.v0_m_s.num
        if c.num * th * v > self.max_points:
            raise ValueError(
                f"continuation.num x continuation.grid.theta0_deg.num x "
                f"continuation.grid.v0_m_s.num = {c.num} x {th} x {v} = {c.num * th * v:,} "
                f"starts, more than max_points = {self.max_points:,}; reduce them or raise "
                "max_points")
        return self


# -- tables -------------------------------------------------------------------------------------
def attractor_rows(attractors: list[Attractor], fractions: dict[int, tuple]) -> pd.DataFrame:
    rows = []
    for a in attractors:
        moduli = np.sort(np.abs(a.multipliers))[::-1]
        share = fractions.get(a.index, (0, 0.0, 0.0, 0.0))
        rows.append({
            "attractor": a.index, "name": a.name, "kind": a.kind, "period": a.period,
            "cycles": a.cycles,
            "theta_deg": float(np.degrees(a.theta[0])) if a.theta.size else math.nan,
            "v_m_s": float(a.v[0]) if a.v.size else math.nan, "points": int(a.theta.size),
            "cells": int(np.unique(a.cells).size),
            "multiplier1_abs": float(moduli[0]) if moduli.size else math.nan,
            "multiplier2_abs": float(moduli[1]) if moduli.size > 1 else math.nan,
            "lyapunov_per_impact": a.lyapunov, "refined": a.refined,
            "basin_count": share[0], "basin_fraction": share[1], "fraction_low": share[2],
            "fraction_high": share[3]})
    return pd.DataFrame(rows, columns=[
        "attractor", "name", "kind", "period", "cycles", "theta_deg", "v_m_s", "points",
        "cells", "multiplier1_abs", "multiplier2_abs", "lyapunov_per_impact", "refined",
        "basin_count", "basin_fraction", "fraction_low", "fraction_high"])


def label_name(label: int, attractors: list[Attractor]) -> str:
    return OTHER_LABELS[label] if label < 0 else attractors[label].name


def paper_class(label: int, attractors: list[Attractor]) -> str:
    """Section 3's classes of the same result: period1 (eq. 8's orbit), sticking, below the
    racket, undecided (everything else the paper's rules cannot name)."""
    if label < 0:
        return {"below_racket": "below_racket", "sticking": "sticking"}.get(
            OTHER_LABELS[label], "undecided")
    a = attractors[label]
    if a.kind == "periodic" and a.period == 1 and a.cycles == 1:
        return "period1"
    return "locked" if a.kind == "locked" else "undecided"


def _fractions_frame(labels, attractors) -> tuple[pd.DataFrame, dict[int, tuple]]:
    fr = basin_fractions(labels)
    frame = pd.DataFrame([{"label": f.label, "name": label_name(f.label, attractors),
                           "count": f.count, "fraction": f.fraction, "low": f.low,
                           "high": f.high} for f in fr])
    return frame, {f.label: (f.count, f.fraction, f.low, f.high) for f in fr}


# -- continuation -------------------------------------------------------------------------------
def _same(a: Attractor, b: Attractor) -> bool:
    """b continues a across a parameter step: the same kind and period, and (periodic) a
    point of b near a point of a (0.3 rad, 0.5 m/s)."""
    if a.kind != b.kind or a.period != b.period or a.cycles != b.cycles:
        return False
    if a.kind != "periodic":
        return True
    dth = np.abs(phase_difference(a.theta[:, None], b.theta[None, :]))
    return bool(np.any((dth < 0.3) & (np.abs(a.v[:, None] - b.v[None, :]) < 0.5)))


def continue_fractions(config: AttractorsConfig, options: RunOptions) -> pd.DataFrame:
    """The shares of every attractor at each parameter value, an attractor continued from one
    value to the next where ``_same`` holds (its ``branch`` number kept). The values are
    independent tasks (``continuation_point``) on ``options.jobs`` workers; the branches are
    matched here, in the values' order, so the table does not depend on the workers."""
    c = config.continuation
    column = parameter_column(c.parameter)  # with its unit: racket_amplitude_m
    values = np.linspace(c.start, c.stop, c.num)
    rows: list[dict] = []
    previous: list[tuple[int, Attractor]] = []
    branches = 0
    options.progress.start(len(values), "continuation")
    tasks = [(config, float(value)) for value in values]
    with parallel.executor(min(options.jobs, len(tasks)), options.scheduler) as executor:
        for value, (attractors, fractions) in zip(values, executor.map(continuation_point,
                                                                      tasks)):
            current: list[tuple[int, Attractor]] = []
            for a in attractors:
                match = next((b for b, old in previous if _same(old, a)), None)
                if match is None:
                    match, branches = branches, branches + 1
                current.append((match, a))
            branch_of = {a.index: b for b, a in current}
            for f in fractions:
                rows.append({column: float(value), "label": f.label,
                             "branch": branch_of.get(f.label, f.label),
                             "name": label_name(f.label, attractors), "fraction": f.fraction,
                             "low": f.low, "high": f.high})
            previous = current
            options.progress.advance(1)
    return pd.DataFrame(rows, columns=[column, "label", "branch", "name", "fraction", "low",
                                       "high"])


#: the model parameters each continued parameter changes (gamma: a_r = gamma g / w_r^2)
CONTINUATION_VARIES = {"gamma": "a_r", "racket_amplitude": "a_r", "racket_period": "tau"}


def continuation_caption(config: AttractorsConfig) -> str:
    """The continuation figure's caption: the model's parameters that stay, the one
    continued over its range, and the continuation's own grid (not the run's main grid).

    Parameters
    ----------
    config : AttractorsConfig
        The run's config (``model`` and ``continuation``).

    Returns
    -------
    str
        e.g. ``alpha = 0.5, g = 9.81 m/s^2, tau = 0.92 s; gamma from 1.4 to 1.8 (17
        values, a_r = gamma g / w_r^2); 90 x 90 starts at each value``.
    """
    c, p = config.continuation, config.params
    kept = {"alpha": f"alpha = {p.alpha:g}", "g": f"g = {p.g:g} m/s^2",
            "a_r": f"a_r = {p.racket_amplitude:g} m", "tau": f"tau = {p.racket_period:g} s"}
    del kept[CONTINUATION_VARIES[c.parameter]]
    values = (f"{c.parameter} = {c.start:g}" if c.num == 1 else
              f"{c.parameter} from {c.start:g} to {c.stop:g} ({c.num} values"
              + (", a_r = gamma g / w_r^2)" if c.parameter == "gamma" else ")"))
    if c.num == 1 and c.parameter == "gamma":
        values += " (a_r = gamma g / w_r^2)"
    grid = f"{c.grid.theta0_deg.num} x {c.grid.v0_m_s.num} starts at each value"
    return "; ".join([", ".join(kept.values()), values, grid])


def continuation_point(task: tuple[AttractorsConfig, float]):
    """One value of the continuation (a worker's task): the attractors ``find_attractors``
    finds on ``continuation.grid`` at it (discovery on the sample ``measures.seed`` draws,
    then the labelling) and each label's share, ``basin_fractions``."""
    config, value = task
    c = config.continuation
    th, vv = np.meshgrid(np.radians(c.grid.theta0_deg.values()), c.grid.v0_m_s.values())
    found = find_attractors(th, vv, parameter_point(config.params, c.parameter, value),
                            config.recurrence.settings(),
                            np.random.default_rng(config.measures.seed))
    return found.attractors, basin_fractions(found.labels)


# -- the run ------------------------------------------------------------------------------------
def run(config: AttractorsConfig, options: RunOptions) -> ExperimentResult:
    params = config.params
    settings = config.recurrence.settings()
    theta_deg, v0 = config.grid.theta0_deg.values(), config.grid.v0_m_s.values()
    th, vv = np.meshgrid(np.radians(theta_deg), v0)
    finder = AttractorFinder(params, settings)
    rng = np.random.default_rng(config.measures.seed)
    pick = rng.choice(th.size, size=min(settings.sample, th.size), replace=False)
    # the recurrences of orbits without a period in threads (the compiled loop releases the
    # GIL), the grid's labelling in worker processes
    with parallel.executor(options.jobs, threads=True) as threads:
        finder.discover(th.ravel()[pick], vv.ravel()[pick], follow=threads.map)
        # said as soon as the sample shows it: with most starts undecided, the labelling
        # that follows takes minutes (alpha 0.9: 5 min with the bundled range, 30 s with a
        # wide one)
        warned = warn_if_beyond_cells(finder, config, options)
        jobs = options.jobs if th.size >= POOL_MIN_POINTS else 1
        with parallel.executor(jobs) as executor:
            labels, impacts = finder.label(th, vv, map=executor.map, workers=executor.workers,
                                           follow=threads.map, progress=options.progress)
        rediscovered = finder.rediscovered  # the grid's (the measures' starts come next)
        if not warned:
            warn_if_beyond_cells(finder, config, options)
        measures = _measures(config, finder, labels, theta_deg, v0, threads.map)
    attractors = finder.attractors
    fractions, shares = _fractions_frame(labels, attractors)
    names = np.array([label_name(x, attractors) for x in range(-4, len(attractors))],
                     dtype=object)
    classes = np.array([paper_class(x, attractors) for x in range(-4, len(attractors))],
                       dtype=object)
    basin = pd.DataFrame({
        "theta0_deg": np.broadcast_to(theta_deg[None, :], th.shape).ravel(),
        "v0_m_s": np.broadcast_to(v0[:, None], th.shape).ravel(),
        "label": labels.ravel(), "attractor": names[labels.ravel() + 4],
        "paper_class": classes[labels.ravel() + 4], "impacts": impacts.ravel()})
    points = pd.DataFrame([{"attractor": a.index, "name": a.name, "theta_deg": math.degrees(t),
                            "v_m_s": v} for a in attractors for t, v in zip(a.theta, a.v)],
                          columns=["attractor", "name", "theta_deg", "v_m_s"])
    frames = {"attractors.csv": attractor_rows(attractors, shares),
              "attractor_points.csv": points, "fractions.csv": fractions, "basin.csv": basin,
              "measures.csv": measures[0], "uncertainty.csv": measures[1]}
    if config.continuation.num:
        frames["continuation.csv"] = continue_fractions(config, options)
    figures = draw(frames, config)
    continued = figures.pop("attractors_continuation.png", None)
    caption_figures(figures, params, f"{th.shape[1]} x {th.shape[0]} starts")
    if continued is not None:  # its own grid, and the parameter it varies
        caption_figures({"continued": continued}, None, continuation_caption(config))
        figures["attractors_continuation.png"] = continued
    return ExperimentResult(frames=frames, figures=figures,
                            summary=summary_lines(attractors, shares, labels.size,
                                                  rediscovered))


def warn_if_beyond_cells(finder: AttractorFinder, config: AttractorsConfig,
                         options: RunOptions) -> bool:
    """Warn, with a range to use, where the orbits followed so far went above
    ``recurrence.v_range_m_s`` (``AttractorFinder.beyond_cells``); True if it warned."""
    beyond = finder.beyond_cells()
    if beyond is None:
        return False
    low, high = config.recurrence.v_range_m_s
    options.warn(f"orbits reached {beyond:.1f} m/s, above recurrence.v_range_m_s "
                 f"[{low:g}, {high:g}], where the cells cannot tell attractors apart: "
                 f"widen it (e.g. --set 'recurrence.v_range_m_s=[{low:g}, "
                 f"{math.ceil(2.0 * beyond):g}]')")
    return True


def summary_lines(attractors, shares: dict[int, tuple], n_starts: int,
                  rediscovered: int) -> list[str]:
    """The run's summary: each attractor's share of the starts, then where the other starts
    went (sticking, below the racket, resting, undecided), so that the shares add up to the
    grid; and how many starts met none of the attractors the sampled discovery catalogued
    and were followed further."""
    count = (f"{len(attractors)} attractor{'s' if len(attractors) != 1 else ''}"
             if attractors else "no attractor")
    parts = [", ".join(f"{a.name} {shares.get(a.index, (0, 0.0))[1]:.1%}" for a in attractors),
             ", ".join(f"{OTHER_LABELS[label].replace('_', ' ')} {shares[label][1]:.1%}"
                       for label in sorted(OTHER_LABELS) if shares.get(label, (0,))[0])]
    return [f"{count} in {n_starts:,} starts: " + "; ".join(p for p in parts if p),
            f"second discovery: {rediscovered:,} starts (orbits that met no catalogued "
            "attractor at first, followed further)"]


#: above this share of undecided starts the basin measures say they do not measure the
#: attractors' basins (measures.csv's notes)
UNDECIDED_CAVEAT = 0.05


def ln2_verdict(value: float, se: float) -> str:
    """measures.csv's reading of S_bb against ln 2 (Daza et al. 2016: above it, a fractal
    boundary, a sufficient condition; below it the test says nothing), by two standard
    errors: a margin within them (0.693167 over 91 boxes) decides nothing."""
    ln2 = math.log(2.0)
    if not math.isfinite(se):
        return f"ln 2 = {ln2:.4f} (too few boundary boxes for a standard error: not tested)"
    if value - 2.0 * se > ln2:
        return f"above ln 2 = {ln2:.4f} by more than 2 SE: a fractal boundary (sufficient)"
    if value + 2.0 * se < ln2:
        return f"below ln 2 = {ln2:.4f} by more than 2 SE: this test is silent"
    return f"within 2 SE of ln 2 = {ln2:.4f}: undecided by this test"


def _measures(config: AttractorsConfig, finder: AttractorFinder, labels, theta_deg, v0,
              follow: Callable = map):
    """(measures.csv, uncertainty.csv): basin entropy, boundary basin entropy (Daza et al.
    2016) and the uncertainty exponent with its SE (McDonald et al. 1985); ``follow`` as
    for ``AttractorFinder.label``."""
    m = config.measures
    rows: list[dict[str, Any]] = []
    if min(labels.shape) >= m.box:
        be = basin_entropy(labels, m.box)
        rows += [{"quantity": "basin_entropy", "value": be.basin_entropy, "se": math.nan,
                  "note": f"{be.boxes} boxes of {m.box} x {m.box} starts"},
                 {"quantity": "boundary_basin_entropy", "value": be.boundary_basin_entropy,
                  "se": be.boundary_basin_entropy_se,
                  "note": f"{be.boundary_boxes} boundary boxes; "
                  + ln2_verdict(be.boundary_basin_entropy, be.boundary_basin_entropy_se)}]
    else:  # said, not left out
        note = (f"not measured: the grid ({labels.shape[1]} x {labels.shape[0]} starts) is "
                f"smaller than one box of measures.box = {m.box} starts a side")
        rows += [{"quantity": q, "value": math.nan, "se": math.nan, "note": note}
                 for q in ("basin_entropy", "boundary_basin_entropy")]
    x_range = (math.radians(theta_deg[0]), math.radians(theta_deg[-1]))
    y_range = (float(v0[0]), float(v0[-1]))
    if x_range[1] > x_range[0] and y_range[1] > y_range[0]:
        ue = uncertainty_exponent(lambda x, y: finder.label(x, y, follow=follow)[0],
                                  x_range, y_range,
                                  np.asarray(m.eps), m.samples, np.random.default_rng(m.seed))
        rows.append({"quantity": "uncertainty_exponent", "value": ue.alpha, "se": ue.alpha_se,
                     "note": "the uncertain fraction f(eps) ~ eps^u, u this value; 1: a "
                     f"smooth boundary, < 1: fractal (dimension 2 - u); {m.samples} starts "
                     "per eps"})
        uncertainty = pd.DataFrame({"eps": ue.eps, "uncertain_fraction": ue.uncertain_fraction})
    else:
        uncertainty = pd.DataFrame(columns=["eps", "uncertain_fraction"])
    undecided = float(np.mean(labels == UNDECIDED))
    if undecided > UNDECIDED_CAVEAT:  # the measures see 'undecided' as one more outcome
        caveat = (f"; {undecided:.0%} of the starts are undecided, which these measures count "
                  "as one outcome: not a measure of the attractors' basins")
        for row in rows:
            row["note"] = f"{row['note']}{caveat}"
    rows.append({"quantity": "undecided_fraction", "value": undecided, "se": math.nan,
                 "note": "starts no attractor was found for within the budgets"})
    return pd.DataFrame(rows, columns=["quantity", "value", "se", "note"]), uncertainty


# -- figures ------------------------------------------------------------------------------------
OTHER_COLOURS = {"below_racket": "#000000", "sticking": "#9a9a9a", "undecided": "#d62728",
                 "resting": "#8c564b"}
PALETTE = ["#4c72b0", "#dd8452", "#55a868", "#8172b3", "#937860", "#da8bc3", "#ccb974",
           "#64b5cd", "#c44e52", "#a1c9f4", "#ffb482", "#8de5a1", "#d0bbff", "#1f77b4"]


def _colours(names: list[str], known: dict[str, str] | None = None) -> dict[str, str]:
    """A colour per name: the starts no attractor took their fixed ones, a name in
    ``known`` (attractors.png's) its colour there, the others the palette's next colours
    not taken, in the order given (so that one attractor has one colour in both figures)."""
    known = known or {}
    out: dict[str, str] = {}
    free = itertools.cycle([c for c in PALETTE if c not in known.values()] or PALETTE)
    for name in names:
        if name in OTHER_COLOURS:
            out[name] = OTHER_COLOURS[name]
        elif name in known:
            out[name] = known[name]
        elif name not in out:
            out[name] = next(free)
    return out


@publication_style
def draw(frames: dict[str, pd.DataFrame], config: AttractorsConfig | None = None) -> dict:
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from .plotting import new_figure

    figures = {}
    basin, fractions = frames["basin.csv"], frames["fractions.csv"]
    points = frames["attractor_points.csv"]
    theta = np.unique(basin["theta0_deg"])
    v = np.unique(basin["v0_m_s"])
    order = list(fractions["name"])
    colours = _colours(order)
    code = {name: i for i, name in enumerate(order)}
    grid = basin["attractor"].map(code).to_numpy().reshape(v.size, theta.size)
    fig, axes = new_figure(width=7.0, height=5.6)
    ax = axes[0, 0]
    ax.imshow(grid, origin="lower", aspect="auto", interpolation="nearest",
              extent=cell_extent(theta, v),
              cmap=ListedColormap([colours[n] for n in order]), vmin=-0.5,
              vmax=len(order) - 0.5)
    # a periodic orbit's points in its colour ringed white and black, a chaotic attractor's
    # sample as black dots: white edges alone vanished where an attractor lies above the grid
    # (white), and a dot in its basin's own colour vanishes inside its basin
    for name, part in points.groupby("name", sort=False):
        if len(part) < 100:  # a ring of white and black around the colour: seen on any ground
            ax.plot(part["theta_deg"], part["v_m_s"], "o", ms=8, mfc="k", mec="k", ls="none")
            ax.plot(part["theta_deg"], part["v_m_s"], "o", ms=6, mfc=colours.get(name, "k"),
                    mec="w", mew=1.0, ls="none")
        else:
            ax.plot(part["theta_deg"], part["v_m_s"], ".", ms=1.5, color="k", ls="none")
    ax.set_xlabel(r"initial phase $\theta_0$ (deg)")
    ax.set_ylabel(r"initial velocity $v_0$ (m/s)")
    ax.set_title("Basins of the attractors found by recurrence (markers: the attractors)")
    handles = [Patch(facecolor=colours[row.name], edgecolor="0.3",
                     label=f"{shown(row.name)}: {row.fraction:.1%}")
               for row in fractions.itertuples()]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=8,
               frameon=False)
    figures["attractors.png"] = fig
    if "continuation.csv" in frames and len(frames["continuation.csv"]):
        figures["attractors_continuation.png"] = _draw_continuation(
            frames["continuation.csv"], config, colours)
    return figures


def shown(name: str) -> str:
    """A label as a legend shows it: ``below_racket`` -> ``below the racket``."""
    return OTHER_NAMES_SHOWN.get(name, name)


#: the tables' names of the starts no attractor took, as the figures' legends say them
OTHER_NAMES_SHOWN = {"below_racket": "below the racket"}


#: attractors_continuation.png's title per continued parameter (Gamma is varied through the
#: racket's amplitude, ``linear.with_parameters``), in two lines: one is wider than the axes
#: beside the legend
CONTINUED_OVER = {
    "gamma": "Basin fractions over Gamma\n(the racket's amplitude varied, its period fixed)",
    "racket_amplitude": "Basin fractions over the racket's amplitude\n(its period fixed)",
    "racket_period": "Basin fractions over the racket's period\n(its amplitude fixed)",
    "alpha": "Basin fractions over the coefficient of restitution",
}


def _draw_continuation(table: pd.DataFrame, config: AttractorsConfig | None,
                       known: dict[str, str] | None = None):
    """attractors_continuation.png: the basin fractions stacked over the continued parameter,
    each attractor in its colour of attractors.png (``known``) where it is there."""
    from .plotting import new_figure

    column = next(c for c in table.columns if column_parameter(c) is not None)
    parameter = column_parameter(column)
    assert parameter is not None
    table = table.rename(columns={column: parameter})
    values = np.unique(table[parameter])
    table = table.assign(key=np.where(table["label"] < 0, table["name"],
                                      "b" + table["branch"].astype(str)))
    keys = list(dict.fromkeys(table.sort_values([parameter, "label"])["key"]))
    first_name = {k: table.loc[table["key"] == k, "name"].iloc[0] for k in keys}
    # a branch is coloured by the attractor it starts as (its first name), so that a name
    # met in attractors.png keeps its colour; a second branch of that name gets its own
    seen: set[str] = set()
    colour_keys = []
    for k in keys:
        name = first_name[k]
        colour_keys.append(name if name not in seen else f"{name} ({k})")
        seen.add(name)
    colours = _colours(colour_keys, known)
    stack = np.zeros((len(keys), values.size))
    for i, k in enumerate(keys):
        part = table[table["key"] == k].groupby(parameter)["fraction"].sum()
        stack[i] = part.reindex(values, fill_value=0.0).to_numpy()
    fig, axes = new_figure(width=7.0, height=4.6)
    ax = axes[0, 0]
    repeated = {n for n in first_name.values() if list(first_name.values()).count(n) > 1}
    labels = [shown(first_name[k]) + (f" (branch {k[1:]})" if first_name[k] in repeated
                                      else "") for k in keys]
    fills = [colours[c] for c in colour_keys]
    if values.size > 1:
        ax.stackplot(values, stack, colors=fills, labels=labels, edgecolor="w", linewidth=0.3)
        ax.set_xlim(values[0], values[-1])
    else:  # one value (continuation.num 1): one stacked bar
        width = 0.1 * max(abs(float(values[0])), 1e-3)
        bottoms = np.concatenate([[0.0], np.cumsum(stack[:, 0])[:-1]])
        ax.bar(np.repeat(values, len(keys)), stack[:, 0], width=width, bottom=bottoms,
               color=fills, label=labels, edgecolor="w", linewidth=0.3)
        ax.set_xlim(values[0] - width, values[0] + width)
    if config is not None:
        th = period1_thresholds(config.params, parameter)
        for x, text in ((th.existence, "eq. 8: period-1 exists"),
                        (th.flip, "eq. 14: period-1 flips")):
            if math.isfinite(x) and values[0] <= x <= values[-1]:
                ax.axvline(x, color="k", ls="--", lw=0.8)
                ax.text(x, 1.01, text, rotation=0, ha="center", va="bottom", fontsize=7,
                        transform=ax.get_xaxis_transform())
    ax.set_ylim(0.0, 1.0)
    ax.set_xlabel(SWEEPABLE[parameter][1])
    ax.set_ylabel("share of the starts (basin fraction)")
    ax.set_title(CONTINUED_OVER.get(parameter, "Basin fractions continued"), pad=14)
    fig.legend(loc="outside right upper", fontsize=7, frameon=False)
    return fig


EXPERIMENT = Experiment(name="attractors", schema=AttractorsConfig, run=run, draw=draw)
