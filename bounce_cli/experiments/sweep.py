"""A basin atlas over parameters (beyond the paper, which shows one basin, Fig. 4).

Over a 1-D or 2-D grid of parameter points (any of alpha, g, racket_amplitude, racket_period,
or ac_g -- the racket acceleration at impact AC of section 4, set through the explicit
amplitude, so that alpha x ac_g is Fig. 5's plane), each point gets the period-1 fixed point
(eqs. 7, 8) and its spectral radius (eq. 10), and a basin on a (theta0, v0) grid classified
as in section 3: the fractions of ``period1``, ``sticking``, ``below_racket`` and
``undecided``, the basin entropy and boundary basin entropy (Daza et al. 2016) and, on
request, the uncertainty exponent (``analysis.sweep``, ``analysis.basin_measures``).

Each parameter point is one task with its own seed (``SeedSequence(seed).spawn``), run on
``--jobs`` local processes or a Dask cluster (``--scheduler``) through ``parallel.executor``;
the results never depend on which. Finished points go to ``RunOptions.checkpoints`` as they
arrive, so that ``--resume`` continues an interrupted sweep (the CLI keeps them in
``<out>/points/``).
"""

from __future__ import annotations

import math
from typing import Any, Literal, Optional

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..runtime import parallel
from ..runtime.config import ClassifyBlock, ConfigError, ExperimentConfig, StrictModel
from ..analysis.classify import EXACT_OUTCOMES, compiled_kernel_available
from ..model.linear import MODEL_FIELDS, flip_boundary_g, radius_below
from ..model.params import ModelError, ModelParams
from ..analysis.sweep import (
    SWEEP_PARAMETERS,
    Axis,
    UncertaintySettings,
    evaluate_point,
    parameter_point,
    point_tasks,
)
from .plotting import caption_figures, publication_style
from .base import Experiment, ExperimentResult, RunOptions
from .basin import GridAxis

Parameter = Literal["alpha", "g", "racket_amplitude", "racket_period", "ac_g"]


class SweepAxis(GridAxis):
    """numpy.linspace(start, stop, num) of one parameter (``ac_g``: AC in g, <= 0)."""

    parameter: Parameter
    num: int = Field(ge=1, le=10_000)


class SweepBlock(StrictModel):
    """The parameter grid: ``x`` alone (a line), or ``x`` by ``y`` (a plane)."""

    x: SweepAxis = SweepAxis(parameter="alpha", start=0.3, stop=0.8, num=6)
    y: Optional[SweepAxis] = SweepAxis(parameter="ac_g", start=-1.6, stop=-0.1, num=6)

    @model_validator(mode="after")
    def _distinct(self):
        if self.y is not None:
            pair = {self.x.parameter, self.y.parameter}
            if len(pair) == 1:
                raise ValueError("x and y must sweep different parameters")
            if pair == {"ac_g", "racket_amplitude"}:
                raise ValueError("ac_g sets the racket amplitude: sweep one of them")
        return self

    def axes(self) -> list[SweepAxis]:
        return [self.x] if self.y is None else [self.x, self.y]


class BasinGridBlock(StrictModel):
    """The basin at each point: numpy.linspace grids of initial conditions."""

    theta0_deg: GridAxis = GridAxis(start=0.0, stop=360.0, num=40)
    v0_m_s: GridAxis = GridAxis(start=0.0, stop=10.0, num=40)


class MeasuresBlock(StrictModel):
    entropy_box: int = Field(5, ge=1, description="cells per box side (basin entropy)")
    uncertainty: bool = Field(False, description="also the uncertainty exponent")
    eps: list[float] = Field([1e-3, 3e-3, 1e-2, 3e-2], min_length=2,
                             description="perturbations, fractions of the grid's spans")
    samples: int = Field(1000, ge=10, description="random initial conditions per eps")

    @model_validator(mode="after")
    def _eps_in_range(self):
        if any(not 0.0 < e < 1.0 for e in self.eps):
            raise ValueError("eps: every value must lie in (0, 1) (a fraction of the span)")
        return self


class LimitsBlock(StrictModel):
    max_basin_points: int = Field(1_000_000_000, ge=1,
                                  description="parameter points x basin points at most")


class SweepConfig(ExperimentConfig):
    sweep: SweepBlock = SweepBlock()
    basin: BasinGridBlock = BasinGridBlock()
    classify: ClassifyBlock = ClassifyBlock()
    measures: MeasuresBlock = MeasuresBlock()
    seed: int = Field(1, ge=0, description="the uncertainty exponent's random points")
    limits: LimitsBlock = LimitsBlock()

    @model_validator(mode="after")
    def _grid_holds_a_box(self):
        box = self.measures.entropy_box
        for key in ("theta0_deg", "v0_m_s"):
            if getattr(self.basin, key).num < box:
                raise ValueError(f"basin.{key}.num must be at least measures.entropy_box "
                                 f"({box}): the basin entropy needs one whole box")
        return self


def parameter_grid(config: SweepConfig) -> tuple[list[ModelParams], np.ndarray]:
    """The parameter points (x fastest, then y) and their grid indices [point, axis]."""
    axes = config.sweep.axes()
    base = config.params
    for corner in np.ndindex(*(2,) * len(axes)):  # the valid ranges are boxes: corners do
        values = {str(a.parameter): (a.start, a.stop)[c] for a, c in zip(axes, corner)}
        try:
            parameter_point(base, values)
        except ModelError as exc:
            keys = " and ".join(f"sweep.{n}.{('start', 'stop')[c]}"
                                for n, c in zip("xy", corner))
            raise ConfigError(f"{keys}: {exc}") from None
    shape = tuple(a.num for a in axes)
    index = np.array([i[::-1] for i in np.ndindex(*shape[::-1])], dtype=int)
    grids = [a.values() for a in axes]
    points = [parameter_point(base, {str(a.parameter): float(g[i])
                                     for a, g, i in zip(axes, grids, idx)})
              for idx in index]
    return points, index


def point_tasks_of(config: SweepConfig, points: list[ModelParams] | None = None):
    """The sweep's tasks, one per parameter point (``points``: from ``parameter_grid``)."""
    if points is None:
        points, _ = parameter_grid(config)
    theta_axis, v_axis = config.basin.theta0_deg, config.basin.v0_m_s
    measures = config.measures
    uncertainty = (UncertaintySettings(tuple(measures.eps), measures.samples)
                   if measures.uncertainty else None)
    return point_tasks(points, Axis(theta_axis.start, theta_axis.stop, theta_axis.num),
                       Axis(v_axis.start, v_axis.stop, v_axis.num),
                       config.classify.settings(), measures.entropy_box, uncertainty,
                       config.seed)


def run(config: SweepConfig, options: RunOptions) -> ExperimentResult:
    axes = config.sweep.axes()
    theta_axis, v_axis = config.basin.theta0_deg, config.basin.v0_m_s
    basin_points = theta_axis.num * v_axis.num
    # counted from the axes before any point is made (10^8 parameter points took minutes and
    # gigabytes to build, only to be refused)
    n_points = math.prod(a.num for a in config.sweep.axes())
    if n_points * basin_points > config.limits.max_basin_points:
        raise ConfigError(
            f"limits.max_basin_points: {n_points:,} parameter points x {basin_points:,} "
            f"basin points = {n_points * basin_points:,}, more than "
            f"limits.max_basin_points = {config.limits.max_basin_points:,}; reduce sweep.*.num "
            "or basin.*.num, or raise limits.max_basin_points")
    points, index = parameter_grid(config)
    tasks = point_tasks_of(config, points)

    done = {i: r for i, r in options.checkpoints.load().items() if 0 <= i < len(tasks)}
    todo = [t for t in tasks if t.index not in done]
    options.progress.start(len(tasks), "sweep: parameter points")
    options.progress.advance(len(done))
    if todo:
        jobs = min(options.jobs, len(todo))
        # the compiled kernel releases the GIL: threads here, no worker start-up
        threads = compiled_kernel_available()
        with parallel.executor(jobs, options.scheduler, threads=threads) as executor:
            for result in executor.map(evaluate_point, todo):
                options.checkpoints.save(result["index"], result)
                done[result["index"]] = result
                options.progress.advance()
    results = [done[t.index] for t in tasks]
    frames = tables(axes, points, index, results)

    sweep = frames["sweep.csv"]
    exists = sweep["fixed_point_v_m_s"].notna()
    names = " x ".join(f"{a.parameter} ({a.num})" for a in axes)
    summary = [
        f"sweep: {len(points)} parameter points ({names}), basin {theta_axis.num} x "
        f"{v_axis.num} at each" + (f"; {len(tasks) - len(todo)} resumed from an interrupted "
                                   f"run" if len(todo) < len(tasks) else ""),
        f"period-1 fixed point at {int(exists.sum())} points, linearly stable at "
        f"{int(radius_below(sweep['spectral_radius']).sum())}; period-1 fraction "
        f"{sweep['fraction_period1'].min():.3f} to {sweep['fraction_period1'].max():.3f}; "
        f"boundary basin entropy up to {sweep['boundary_basin_entropy'].max():.3f} "
        f"(ln 2 = {math.log(2):.3f})",
    ]
    figures = draw(frames)
    caption_figures(figures, None, caption(config))
    return ExperimentResult(frames=frames, figures=figures, summary=summary)


def caption(config: SweepConfig) -> str:
    """The parameters held fixed and those swept (figure titles)."""
    swept = {a.parameter for a in config.sweep.axes()}
    if "ac_g" in swept:
        swept.add("racket_amplitude")
    params = config.params
    fixed = {"alpha": f"alpha = {params.alpha:g}", "g": f"g = {params.g:g} m/s^2",
             "racket_amplitude": f"a_r = {params.racket_amplitude:g} m",
             "racket_period": f"tau = {params.racket_period:g} s"}
    held = ", ".join(text for key, text in fixed.items() if key not in swept)
    grid = config.basin
    return (f"{held}; swept: {' x '.join(a.parameter for a in config.sweep.axes())}; "
            f"basin {grid.theta0_deg.num} x {grid.v0_m_s.num} at each point")


def tables(axes: list[SweepAxis], points: list[ModelParams], index: np.ndarray,
           results: list[dict]) -> dict[str, pd.DataFrame]:
    """sweep.csv (one row per point), axes.csv (the grid) and, with the uncertainty
    exponent, uncertainty.csv (f(eps) per point)."""
    columns: dict[str, Any] = {"point": np.arange(len(points))}
    for k, name in enumerate(("ix", "iy")[: len(axes)]):
        columns[name] = index[:, k]
    for field in MODEL_FIELDS:
        columns[SWEEP_PARAMETERS[field][0]] = [getattr(p, field) for p in points]
    columns["gamma"] = [p.gamma for p in points]
    sweep = pd.concat([pd.DataFrame(columns), pd.DataFrame([r["row"] for r in results])],
                      axis=1)
    axes_frame = pd.DataFrame({
        "axis": ["x", "y"][: len(axes)],
        "parameter": [a.parameter for a in axes],
        "column": [SWEEP_PARAMETERS[a.parameter][0] for a in axes],
        "start": [a.start for a in axes],
        "stop": [a.stop for a in axes],
        "num": [a.num for a in axes],
    })
    frames = {"sweep.csv": sweep, "axes.csv": axes_frame}
    if results and results[0]["uncertainty"] is not None:
        frames["uncertainty.csv"] = pd.DataFrame([
            {"point": r["index"], "eps": e, "uncertain_fraction": f}
            for r in results
            for e, f in zip(r["uncertainty"]["eps"], r["uncertainty"]["uncertain_fraction"])
        ])
    return frames


#: the quantities drawn, with their labels
QUANTITIES = {
    **{f"fraction_{o}": f"fraction {o.replace('_', ' ')}" for o in EXACT_OUTCOMES},
    "spectral_radius": "spectral radius of the fixed point (eq. 10)",
    "basin_entropy": "basin entropy $S_b$ (nats)",
    "boundary_basin_entropy": "boundary basin entropy $S_{bb}$ (nats)",
    "uncertainty_exponent": "uncertainty exponent",
}


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """sweep.png from sweep.csv and axes.csv: heat maps of each quantity over a 2-D sweep
    (the spectral radius 1 contour dashed on each; grey: no value, i.e. no fixed point, or an
    uncertainty exponent withheld), lines over a 1-D."""
    sweep, axes = frames["sweep.csv"], frames["axes.csv"]
    quantities = [q for q in QUANTITIES if q in sweep.columns]
    if len(axes) == 1:
        return {"sweep.png": _draw_line(sweep, axes.iloc[0], quantities)}
    return {"sweep.png": _draw_plane(sweep, axes, quantities)}


def _axis_values(axis) -> np.ndarray:
    return np.linspace(axis["start"], axis["stop"], int(axis["num"]))


def _draw_plane(sweep: pd.DataFrame, axes: pd.DataFrame, quantities: list[str]):
    from .plotting import new_figure

    x_axis, y_axis = axes.iloc[0], axes.iloc[1]
    xs, ys = _axis_values(x_axis), _axis_values(y_axis)
    ncols = 4
    nrows = -(-len(quantities) // ncols)
    fig, panels = new_figure(nrows, ncols, width=15, height=3.4 * nrows + 0.6)
    extent = (*_edges(xs), *_edges(ys))

    def image(column: str) -> np.ndarray:
        out = np.full((ys.size, xs.size), np.nan)
        out[sweep["iy"].to_numpy(), sweep["ix"].to_numpy()] = sweep[column].to_numpy()
        return out

    import matplotlib

    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="0.75")  # grey: NaN
    radius = image("spectral_radius")
    plane = (str(x_axis["parameter"]), str(y_axis["parameter"]))
    for k, ax in enumerate(panels.ravel()):
        if k >= len(quantities):
            ax.set_visible(False)
            continue
        q = quantities[k]
        fraction = q.startswith("fraction_")
        im = ax.imshow(image(q), origin="lower", extent=extent, aspect="auto", cmap=cmap,
                       interpolation="nearest", vmin=0 if fraction else None,
                       vmax=1 if fraction else None)
        fig.colorbar(im, ax=ax, label=QUANTITIES[q])
        _draw_flip_boundary(ax, plane, xs, ys, radius)
        ax.set_xlabel(SWEEP_PARAMETERS[x_axis["parameter"]][1])
        ax.set_ylabel(SWEEP_PARAMETERS[y_axis["parameter"]][1])
        ax.set_title(QUANTITIES[q].split(" (")[0], fontsize=9)
    fig.suptitle("Basin atlas over parameters (grey: no value: no period-1 fixed point, eq. "
                 "8, or too few uncertain points for the exponent; dashed: spectral radius 1, "
                 "eq. 14's flip boundary)" if "uncertainty_exponent" in quantities else
                 "Basin atlas over parameters (grey: no period-1 fixed point, eq. 8; "
                 "dashed: spectral radius 1, eq. 14's flip boundary)")
    return fig


def _draw_flip_boundary(ax, plane: tuple[str, str], xs: np.ndarray, ys: np.ndarray,
                        radius: np.ndarray) -> None:
    """Where the fixed point loses stability: in the alpha x AC plane eq. 14's closed form
    AC = -2 (1 + alpha^2) / (1 + alpha)^2; elsewhere the contour of the sweep's spectral
    radius at 1 (interpolated between the points)."""
    style = dict(color="white", ls="--", lw=1.2)
    if set(plane) == {"alpha", "ac_g"}:
        alpha_axis = xs if plane[0] == "alpha" else ys
        alpha = np.linspace(alpha_axis[0], alpha_axis[-1], 200)
        flip = flip_boundary_g(alpha)
        limits = ys if plane[0] == "alpha" else xs
        inside = (flip >= limits[0]) & (flip <= limits[-1])
        if inside.any():
            x, y = (alpha, flip) if plane[0] == "alpha" else (flip, alpha)
            ax.plot(np.where(inside, x, np.nan), np.where(inside, y, np.nan), **style)
        return
    finite = radius[np.isfinite(radius)]
    if xs.size > 1 and ys.size > 1 and finite.size and finite.min() < 1 < finite.max():
        ax.contour(xs, ys, radius, levels=[1.0], colors="white", linestyles="--",
                   linewidths=1.2)


def _edges(values: np.ndarray) -> tuple[float, float]:
    """Outer cell edges of a linspace axis (one value: one unit wide)."""
    step = float(values[-1] - values[0]) / (values.size - 1) if values.size > 1 else 1.0
    return float(values[0]) - step / 2, float(values[-1]) + step / 2


def _draw_line(sweep: pd.DataFrame, axis, quantities: list[str]):
    from .plotting import new_figure

    x = _axis_values(axis)[sweep["ix"].to_numpy()]
    has_exponent = "uncertainty_exponent" in quantities
    fig, panels = new_figure(3 + has_exponent, 1, width=7.5, height=2.4 * (3 + has_exponent),
                             sharex=True)
    ax = panels[0, 0]
    for o in EXACT_OUTCOMES:  # locked and resting with exact sticking only
        if f"fraction_{o}" in sweep:
            ax.plot(x, sweep[f"fraction_{o}"], "o-", ms=3, label=o.replace("_", " "))
    ax.set_ylabel("fraction of the basin grid")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=8, ncol=2)
    ax = panels[1, 0]
    ax.plot(x, sweep["spectral_radius"], "o-", ms=3, color="black")
    ax.axhline(1.0, color="0.5", ls="--", lw=1, label="1 (stability limit, eq. 14)")
    ax.set_ylabel("spectral radius (eq. 10)")
    ax.legend(fontsize=8)
    ax = panels[2, 0]
    ax.plot(x, sweep["basin_entropy"], "o-", ms=3, label="basin entropy $S_b$")
    ax.plot(x, sweep["boundary_basin_entropy"], "s-", ms=3,
            label="boundary basin entropy $S_{bb}$")
    ax.axhline(math.log(2), color="0.5", ls="--", lw=1,
               label=r"$\ln 2$ (fractal if $S_{bb}$ above)")
    ax.set_ylabel("entropy (nats)")
    ax.legend(fontsize=8)
    if has_exponent:
        ax = panels[3, 0]
        ax.errorbar(x, sweep["uncertainty_exponent"], yerr=sweep["uncertainty_exponent_se"],
                    fmt="o-", ms=3, color="black", capsize=2)
        ax.axhline(1.0, color="0.5", ls="--", lw=1, label="1 (smooth boundary)")
        ax.set_ylabel("uncertainty exponent")
        ax.legend(fontsize=8)
    panels[-1, 0].set_xlabel(SWEEP_PARAMETERS[axis["parameter"]][1])
    fig.suptitle("Basin atlas along one parameter")
    return fig


EXPERIMENT = Experiment(name="sweep", schema=SweepConfig, run=run, draw=draw)
