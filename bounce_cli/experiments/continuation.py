"""Periodic orbits followed in one parameter, with their bifurcations located exactly.

Each start (eq. 8's period-1 orbit hopping m racket cycles, or the periodic orbit an initial
condition settles on) is converged by Newton on F^p(x) = x + (0, 2 pi m) (eqs. 5, 6) and
followed both ways by pseudo-arclength continuation (``analysis.continuation``) with the map's
analytic Jacobian (section 4's implicit-function derivatives along the orbit) and analytic
parameter derivatives. Flips (an eigenvalue -1), folds (+1), Neimark-Sacker points (a
complex pair on the unit circle) and grazings (a flight touching the racket) are located by
test functions and Newton on the augmented system; at a flip the doubled orbit is switched
onto and followed in turn, so the period-doubling cascade is followed to ``max_period`` and
Feigenbaum's delta estimated from its flips. The figure draws the branches over the
brute-force bifurcation diagram (``analysis.bifurcation``: the map iterated from several
initial conditions at every value, as ``bounce bifurcation``).
"""

from __future__ import annotations

import math
from typing import Literal, Optional

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..runtime.config import ConfigError, ExperimentConfig, StrictModel
from ..memory import check_array_memory
from ..model.params import MIN_HOP_S, ModelError
from ..analysis.bifurcation import (
    SweepSettings,
    iterate_sweep,
    parameter_column,
    parameter_point,
    period1_thresholds,
    sweep_parameters,
)
from ..analysis.continuation import (
    Continuation,
    ContinuationSettings,
    eq8_orbit,
    feigenbaum_ratios,
    orbit_by_iteration,
)
from .bifurcation import orbit_frames
from .plotting import caption_figures, publication_style
from .base import Experiment, ExperimentResult, RunOptions

Parameter = Literal["gamma", "racket_amplitude", "racket_period", "alpha"]
#: Feigenbaum's constant delta (the limit the ratios of successive flips should approach)
FEIGENBAUM_DELTA = 4.669201609


class RangeBlock(StrictModel):
    """The parameter continued and the interval its branches are followed in."""

    parameter: Parameter = "gamma"
    low: float = 1.0
    high: float = 2.6

    @model_validator(mode="after")
    def _ordered(self):
        if not self.low < self.high:
            raise ValueError("low must be less than high")
        return self


class StartBlock(StrictModel):
    """One branch's start at the parameter value ``at``: eq. 8's period-1 orbit hopping
    ``cycles`` racket cycles, or (with theta0_deg and v0_m_s) the periodic orbit the map
    settles on from that initial condition."""

    at: float
    cycles: int = Field(1, ge=1, le=50)
    theta0_deg: Optional[float] = None
    v0_m_s: Optional[float] = None

    @model_validator(mode="after")
    def _both_or_neither(self):
        if (self.theta0_deg is None) != (self.v0_m_s is None):
            raise ValueError("give theta0_deg and v0_m_s together (or neither: eq. 8's orbit)")
        return self


class StepBlock(StrictModel):
    initial_step: float = Field(1e-3, gt=0.0, description="arclength, scaled coordinates")
    min_step: float = Field(1e-7, gt=0.0)
    max_step: float = Field(2e-2, gt=0.0)
    max_points: int = Field(2000, ge=1, description="per branch and direction")
    max_period: int = Field(32, ge=1, le=1024, description="doubled branches up to this period")
    switch_step: float = Field(1e-4, gt=0.0, description="along the flip's eigenvector")

    @model_validator(mode="after")
    def _ordered(self):
        if not self.min_step <= self.initial_step <= self.max_step:
            raise ValueError("steps must satisfy min_step <= initial_step <= max_step")
        return self

    def settings(self) -> ContinuationSettings:
        return ContinuationSettings(**self.model_dump())


class FindBlock(StrictModel):
    """Finding a start's periodic orbit by iterating the map (starts with theta0_deg)."""

    transient_impacts: int = Field(3000, ge=0)
    max_period: int = Field(64, ge=1)
    tolerance: float = Field(1e-9, gt=0.0, description="m/s and rad")


class DiagramBlock(StrictModel):
    """The brute-force bifurcation diagram drawn under the branches (as bounce bifurcation)."""

    num: int = Field(240, ge=2, le=100_000, description="values over [low, high]")
    theta0_deg: list[float] = Field([45.0, 90.0], min_length=1, max_length=100)
    v0_m_s: list[float] = Field([3.0, 5.0, 9.0], min_length=1, max_length=100)
    transient_impacts: int = Field(600, ge=0)
    recorded_impacts: int = Field(64, ge=2)
    min_hop_s: float = Field(MIN_HOP_S, ge=0.0, description="s, shorter hops are sticking")

    @model_validator(mode="after")
    def _fits_in_memory(self):
        orbits = self.num * len(self.theta0_deg) * len(self.v0_m_s)
        check_array_memory(orbits * self.recorded_impacts,
                           f"num x initial conditions x recorded_impacts = {self.num:,} x "
                           f"{len(self.theta0_deg) * len(self.v0_m_s):,} x "
                           f"{self.recorded_impacts:,} impacts", "reduce them")
        return self


class ContinuationConfig(ExperimentConfig):
    range: RangeBlock = RangeBlock()
    starts: list[StartBlock] = Field(
        default_factory=lambda: [StartBlock(at=1.3, cycles=1), StartBlock(at=2.2, cycles=2)],
        min_length=1, max_length=20)
    steps: StepBlock = StepBlock()
    find: FindBlock = FindBlock()
    diagram: DiagramBlock = DiagramBlock()


def start_orbit(config: ContinuationConfig, index: int, start: StartBlock):
    """(v, theta, cycles, hops) of a start, or ConfigError naming it."""
    key = f"starts[{index}]"
    try:
        params = parameter_point(config.params, config.range.parameter, start.at)
        if start.theta0_deg is None or start.v0_m_s is None:
            v, theta = eq8_orbit(params, start.cycles)
            return v, theta, start.cycles, [2.0 * math.pi * start.cycles]
        found = orbit_by_iteration(math.radians(start.theta0_deg), start.v0_m_s, params,
                                   transient=config.find.transient_impacts,
                                   max_period=config.find.max_period,
                                   tolerance=config.find.tolerance)
    except ModelError as exc:
        raise ConfigError(f"{key}: {exc}") from None
    return found.v, found.theta, found.cycles, list(found.hops)


def run(config: ContinuationConfig, options: RunOptions) -> ExperimentResult:
    rng = config.range
    for index, start in enumerate(config.starts):
        if not rng.low <= start.at <= rng.high:
            raise ConfigError(f"starts[{index}].at: {start.at:g} is outside range.low .. "
                              f"range.high ({rng.low:g} .. {rng.high:g})")
    for key in ("low", "high"):
        try:
            parameter_point(config.params, rng.parameter, getattr(rng, key))
        except ModelError as exc:
            raise ConfigError(f"range.{key}: {exc}") from None
    column = parameter_column(rng.parameter)
    settings = config.steps.settings()

    branch_rows, orbit_rows, bif_rows = [], [], []
    options.progress.start(len(config.starts), "continuation: branches")
    branch_id = 0
    for index, start in enumerate(config.starts):
        v0, theta0, cycles, hops = start_orbit(config, index, start)
        cont = Continuation(config.params, rng.parameter, rng.low, rng.high, settings)
        try:
            cont.run(start.at, v0, theta0, cycles, hops)
        except ModelError as exc:
            raise ConfigError(f"starts[{index}]: {exc}") from None
        ids = {}
        for b in cont.branches:
            ids[id(b)] = branch_id
            parent = ids[id(cont.branches[b.parent])] if b.parent >= 0 else -1
            for k, (pt, segment) in enumerate(zip(b.points, b.segments)):
                lam = pt.eigenvalues
                branch_rows.append({
                    "branch": branch_id, "start": index, "parent_branch": parent,
                    "period": b.period, "cycles": b.cycles, "segment": segment, "point": k,
                    column: pt.value, "v_m_s": pt.v, "theta_deg": math.degrees(pt.theta),
                    "lambda1_re": lam[0].real, "lambda1_im": lam[0].imag,
                    "lambda2_re": lam[1].real, "lambda2_im": lam[1].imag,
                    "spectral_radius": float(np.max(np.abs(lam))),
                    "stable": pt.stable, "physical": pt.physical,
                    "min_gap_m": pt.tests["grazing"],
                })
                for j in range(b.period):
                    orbit_rows.append({"branch": branch_id, "segment": segment, "point": k,
                                       "impact": j, column: pt.value,
                                       "v_m_s": pt.impact_v[j],
                                       "theta_deg": math.degrees(pt.impact_theta[j]),
                                       "stable": pt.stable, "physical": pt.physical})
            branch_id += 1
        for bif in cont.bifurcations:
            bif_rows.append({"type": bif.kind, "start": index, "period": bif.period,
                             "cycles": bif.cycles, column: bif.value, "v_m_s": bif.v,
                             "theta_deg": math.degrees(bif.theta),
                             "test_function_residual": bif.residual})
        options.progress.advance(1)

    branches = pd.DataFrame(branch_rows)
    orbits = pd.DataFrame(orbit_rows)
    bifurcations = closed_forms(pd.DataFrame(bif_rows, columns=[
        "type", "start", "period", "cycles", column, "v_m_s", "theta_deg",
        "test_function_residual"]), config, column)
    feigenbaum = cascade_table(bifurcations, column)
    diagram, diagram_orbits = brute_force_diagram(config, column, options)
    frames = {"branches.csv": branches, "orbits.csv": orbits, "bifurcations.csv": bifurcations,
              "feigenbaum.csv": feigenbaum, "diagram.csv": diagram,
              "diagram_orbits.csv": diagram_orbits}
    figures = draw(frames)
    base = config.params
    fixed = {"alpha": f"alpha = {base.alpha:g}", "g": f"g = {base.g:g} m/s^2",
             "racket_amplitude": f"a_r = {base.racket_amplitude:g} m",
             "racket_period": f"tau = {base.racket_period:g} s"}
    fixed.pop("racket_amplitude" if rng.parameter == "gamma" else rng.parameter)
    caption_figures(figures, None, ", ".join(fixed.values())
                    + f"; {rng.parameter} from {rng.low:g} to {rng.high:g}")
    return ExperimentResult(frames=frames, figures=figures,
                            summary=summary_lines(bifurcations, feigenbaum, column))


def closed_forms(bifurcations: pd.DataFrame, config: ContinuationConfig,
                 column: str) -> pd.DataFrame:
    """Eq. 8's existence (the fold of the period-1 orbit hopping m cycles) and eq. 14's flip
    beside the located period-1 folds and flips, with the relative difference."""
    closed = []
    for row in bifurcations.itertuples(index=False):
        value = math.nan
        if row.period == 1 and row.type in ("fold", "flip"):
            th = period1_thresholds(config.params, config.range.parameter, int(row.cycles))
            value = th.existence if row.type == "fold" else th.flip
        closed.append(value)
    out = bifurcations.copy()
    out[f"closed_form_{column}"] = closed
    out["closed_form_equation"] = [
        ("eq. 8" if t == "fold" else "eq. 14") if np.isfinite(c) else ""
        for t, c in zip(out["type"], closed)]
    out["relative_difference"] = out[column] / out[f"closed_form_{column}"] - 1.0
    return out


def cascade_table(bifurcations: pd.DataFrame, column: str) -> pd.DataFrame:
    """Per start, its flips in the order of the cascade (periods p, 2p, 4p, ...) and
    delta_n = (lambda_n - lambda_{n-1}) / (lambda_{n+1} - lambda_n)."""
    rows = []
    flips = bifurcations[bifurcations["type"] == "flip"]
    for start, group in flips.groupby("start", sort=True):
        group = group.sort_values("period")
        values = group[column].to_numpy(float)
        deltas = feigenbaum_ratios(values) if values.size >= 3 else np.array([])
        for n, row in enumerate(group.itertuples(index=False)):
            delta = deltas[n - 1] if 1 <= n <= deltas.size else math.nan
            rows.append({"start": int(start), "n": n + 1, "period": int(row.period),
                         "cycles": int(row.cycles), f"flip_{column}": getattr(row, column),
                         "delta": delta,
                         "delta_minus_feigenbaum": delta - FEIGENBAUM_DELTA})
    return pd.DataFrame(rows, columns=["start", "n", "period", "cycles", f"flip_{column}",
                                       "delta", "delta_minus_feigenbaum"])


def brute_force_diagram(config: ContinuationConfig, column: str,
                        options: RunOptions) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The map iterated from every diagram initial condition at ``diagram.num`` values
    (``diagram.theta0_deg`` x ``diagram.v0_m_s``, theta0 slowest, numbered as
    ``initial_condition``): ``diagram.csv``, the recorded impacts (v, wrapped theta) of the
    orbits that did not stick, and ``diagram_orbits.csv``, one row per orbit as ``bounce
    bifurcation``'s ``attractors.csv`` (its attractor, period, sticking impact and how much a
    perturbation of its start grew: what a last bit can decide)."""
    d, rng = config.diagram, config.range
    values = np.linspace(rng.low, rng.high, d.num)
    theta0_deg, v0 = (a.ravel() for a in np.meshgrid(np.asarray(d.theta0_deg, float),
                                                      d.v0_m_s, indexing="ij"))
    settings = SweepSettings(transient_impacts=d.transient_impacts,
                             measured_impacts=d.recorded_impacts,
                             recorded_impacts=d.recorded_impacts,
                             max_period=d.recorded_impacts // 2, min_hop_s=d.min_hop_s)
    params = sweep_parameters(config.params, rng.parameter, np.repeat(values, theta0_deg.size))
    options.progress.start(settings.transient_impacts + settings.measured_impacts,
                           "continuation: brute-force diagram")
    orbits = iterate_sweep(np.tile(np.radians(theta0_deg), values.size),
                           np.tile(v0, values.size), params, settings, options.progress.advance)
    attractors, points, _ = orbit_frames(column, values, theta0_deg, v0, params, orbits,
                                         settings)
    return points, attractors


def summary_lines(bifurcations: pd.DataFrame, feigenbaum: pd.DataFrame,
                  column: str) -> list[str]:
    lines = []
    for row in bifurcations.itertuples(index=False):
        rec = row._asdict()
        text = (f"{row.type} of the period-{row.period} orbit over {row.cycles} racket "
                f"cycle(s): {column} = {rec[column]:.12g}")
        closed = rec[f"closed_form_{column}"]
        if np.isfinite(closed):
            text += (f" ({row.closed_form_equation}: {closed:.12g}, relative difference "
                     f"{row.relative_difference:+.1e})")
        lines.append(text)
    for start, group in feigenbaum.groupby("start"):
        deltas = group["delta"].dropna()
        if not deltas.empty:
            lines.append(f"start {start}: Feigenbaum ratios delta_n = "
                         + ", ".join(f"{x:.4f}" for x in deltas)
                         + f" (Feigenbaum's delta {FEIGENBAUM_DELTA:.4f})")
    return lines


# -- figure ----------------------------------------------------------------------------------
@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """continuation.png: the branches' impact velocities over the brute-force diagram (stable
    solid, unstable dashed, non-physical parts omitted), the located bifurcations marked;
    below, the multiplier of largest modulus along each branch. From the CSVs alone."""
    from .plotting import sweep_figure

    orbits, bifs = frames["orbits.csv"], frames["bifurcations.csv"]
    branches, diagram = frames["branches.csv"], frames["diagram.csv"]
    column = diagram.columns[0]
    fig, top, bottom = sweep_figure(column)
    top.plot(diagram[column], diagram["v_m_s"], ".", ms=0.8, mew=0, color="black", zorder=3,
             rasterized=True)
    top.plot([], [], ".", color="black", label="brute force: the map iterated (attractors)")
    colours: dict[int, str] = {}
    palette = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
               "tab:pink", "tab:olive", "tab:cyan"]
    for b, group in orbits[orbits["physical"].astype(bool)].groupby("branch", sort=True):
        period = int(branches.loc[branches.branch == b, "period"].iloc[0])
        if period not in colours:
            colours[period] = palette[len(colours) % len(palette)]
            top.plot([], [], "-", color=colours[period], label=f"period {period}")
        for _, imp in group.groupby(["segment", "impact"]):
            for stable, style in ((True, "-"), (False, "--")):
                part = imp[column].where(imp["stable"].astype(bool) == stable)
                top.plot(part, imp["v_m_s"], style, color=colours[period],
                         lw=1.0 if stable else 0.6, alpha=1.0 if stable else 0.6, zorder=2)
    top.plot([], [], "-", color="0.3", label="continued: stable")
    top.plot([], [], "--", color="0.3", lw=0.6, label="continued: unstable")
    markers = {"flip": ("o", "black"), "fold": ("s", "tab:blue"),
               "neimark_sacker": ("D", "tab:green"), "grazing": ("x", "tab:red")}
    for kind, (marker, colour) in markers.items():
        sel = bifs[bifs["type"] == kind]
        if not sel.empty:
            top.plot(sel[column], sel["v_m_s"], marker, color=colour, ms=5, mfc="none",
                     zorder=4, label=kind.replace("_", "-"))
    top.set_ylabel(r"ball velocity after impact $v_k$ (m/s)")
    top.set_title("Periodic orbits continued over the brute-force bifurcation diagram "
                  "(eqs. 5, 6)")
    for _, group in branches[branches["physical"].astype(bool)].groupby("branch", sort=True):
        period = int(group["period"].iloc[0])
        order = group.sort_values(["segment", "point"])
        for _, part in order.groupby("segment"):
            bottom.plot(part[column], part["spectral_radius"], color=colours[period], lw=0.9)
    bottom.axhline(1.0, color="black", lw=0.6)
    bottom.set_yscale("log")
    bottom.set_ylim(1e-2, 1e3)
    bottom.set_ylabel("largest $|$multiplier$|$\n(of the period-$p$ map)")
    handles, labels = top.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=7, frameon=False)
    return {"continuation.png": fig}


EXPERIMENT = Experiment(name="continuation", schema=ContinuationConfig, run=run, draw=draw)
