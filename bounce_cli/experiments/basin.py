"""Basin of attraction of the period-1 attractor (section 3, Fig. 4).

Every initial condition (theta0, v0) of a grid -- the ball leaves the racket at phase theta0
with velocity v0 -- is classified by iterating the map (eqs. 5, 6) until it reaches the
period-1 fixed point, sticks, or (never, on the paper's grid) runs out of impacts; initial
velocities not above the racket's are "below the racket". The numerics live in
``analysis.classify``; this module builds the grid, tiles it over worker processes and draws.
"""

from __future__ import annotations

import functools
import importlib.util
import math
from typing import TYPE_CHECKING, Any, Callable, Collection, Literal

import numpy as np
from pydantic import Field, model_validator

from ..paper import values as paper
from ..runtime import parallel
from ..memory import check_array_memory
from ..runtime.config import (
    ClassifyBlock,
    ConfigError,
    ControllableModelBlock,
    ExperimentConfig,
    StrictModel,
)
from ..analysis.classify import (
    EXACT_OUTCOMES,
    OUTCOMES,
    Classification,
    ClassifySettings,
    classify_batch,
    classify_grid,
    compiled_kernel_available,
    has_compiled_kernel,
    load_compiled_kernel,
    outcome_names,
    passive_map,
)
from ..model.control import ControlledMap, is_passive
from ..model.maps import ImpactMap
from ..model.linear import is_stable, stability
from ..model.params import ModelParams
from ..runtime.figure_files import DeferredFigure
from ..runtime.interrupts import lasting_imports
from .plotting import cell_colours, cell_extent, publication_style
from .base import Experiment, ExperimentResult, RunOptions

if TYPE_CHECKING:
    import pandas as pd

#: colours of the outcomes in basin.png (the paper: white, grey, black; undecided: red)
OUTCOME_COLOURS = {
    "period1": "#ffffff",
    "sticking": "#9a9a9a",
    "below_racket": "#000000",
    "undecided": "#d62728",
    "locked": "#6a8fc7",
    "resting": "#8c564b",
}
OUTCOME_LABELS = {
    "period1": "period-1 (reaches the fixed point)",
    "sticking": "sticking",
    "below_racket": "below the racket",
    "undecided": "undecided (max impacts)",
    "locked": "locked: exact sticking solution",
    "resting": "resting on the racket (Gamma <= 1)",
}

LEGEND_BELOW: dict[str, Any] = dict(loc="outside lower center", ncol=3, fontsize=8, frameon=False)


#: below this many grid points the basin is classified in this process whatever --jobs says
#: (numpy kernel only: the compiled kernel runs in threads, which cost nothing to start):
#: starting two worker processes costs about 0.15 s (each imports numpy and the classifier
#: only; 0.8 s when they imported scipy too), and one core classifies about 200,000 points/s
#: of the paper's grid; measured on the shared 2-core machine: 400 x 400 in 0.78 s
#: in-process vs 0.76-0.84 s with 2 workers, 300 x 300 0.42 vs 0.39-0.55 s; 1000 x 1000
#: end to end 6.5 s vs 4.3 s
POOL_MIN_POINTS = 400_000

#: below this many grid points the numpy kernel classifies even where the compiled one is
#: installed: loading numba and the cached kernel costs about 0.35 s, which the compiled
#: kernel (1.7 us a point against 5.3 us, one core) repays from about 100,000 points
COMPILED_MIN_POINTS = 100_000

#: basin.csv bytes per row (the paper's grid: 10.7 MB for 160,000 rows) and the size above
#: which the run warns before computing
CSV_BYTES_PER_ROW = 67
CSV_WARN_BYTES = 500_000_000
#: memory of a basin run per grid point, bytes: the grid, its classification, the table and
#: its CSV text (measured: 170 MB more for 1000 x 1000 points than for 300 x 300)
MEMORY_BYTES_PER_POINT = 190
#: basin.npz bytes per row: three float64 columns, int8 outcome codes, int16 iterations
NPZ_BYTES_PER_ROW = 27
#: output.format -> the file name of the grid's table (artifacts writes it by its suffix)
BASIN_TABLES = {"csv": "basin.csv", "npz": "basin.npz", "parquet": "basin.parquet"}


class GridAxis(StrictModel):
    """numpy.linspace(start, stop, num): endpoints included; ``num: 1`` is the one value
    ``start`` (a basin along a line, or at one initial condition)."""

    start: float
    stop: float
    num: int = Field(ge=1)

    @model_validator(mode="after")
    def _increasing(self):
        if self.num > 1 and not self.stop > self.start:
            raise ValueError(f"stop ({self.stop:g}) must be greater than start ({self.start:g})")
        check_array_memory(self.num, f"num = {self.num:,} values", "reduce num")
        return self

    def values(self) -> np.ndarray:
        return np.linspace(self.start, self.stop, self.num)


class GridBlock(StrictModel):
    theta0_deg: GridAxis = GridAxis(start=0.0, stop=360.0, num=400)
    v0_m_s: GridAxis = GridAxis(start=0.0, stop=10.0, num=400)


class LimitsBlock(StrictModel):
    max_points: int = Field(100_000_000, ge=1, description="largest grid accepted")


class OutputBlock(StrictModel):
    format: Literal["csv", "npz", "parquet"] = Field(
        "csv", description="file format of the grid's table: basin.csv, basin.npz (numpy) or "
        "basin.parquet (needs pyarrow); the small tables are CSV always")


class BasinConfig(ExperimentConfig):
    model: ControllableModelBlock = ControllableModelBlock()
    grid: GridBlock = GridBlock()
    classify: ClassifyBlock = ClassifyBlock()
    limits: LimitsBlock = LimitsBlock()
    output: OutputBlock = OutputBlock()


def run(config: BasinConfig, options: RunOptions) -> ExperimentResult:
    params = config.params
    # the grid's size from the config, before any of it is allocated
    n_theta, n_v = config.grid.theta0_deg.num, config.grid.v0_m_s.num
    n_points = n_theta * n_v
    if n_points > config.limits.max_points:
        raise ConfigError(
            f"limits.max_points: the grid has {n_points:,} points ({n_theta} x {n_v}), about "
            f"{format_bytes(n_points * MEMORY_BYTES_PER_POINT)} of memory, more than "
            f"limits.max_points = {config.limits.max_points:,}; reduce grid.*.num or raise "
            "limits.max_points"
        )
    theta_deg = config.grid.theta0_deg.values()
    v0 = config.grid.v0_m_s.values()
    table = BASIN_TABLES[config.output.format]
    if config.output.format == "parquet" and importlib.util.find_spec("pyarrow") is None:
        raise ConfigError(
            "output.format: parquet needs the pyarrow package "
            "(pip install 'bounce-cli[parquet]'), or use output.format=npz (numpy only)"
        )
    csv_bytes = n_points * CSV_BYTES_PER_ROW
    if config.output.format == "csv" and csv_bytes > CSV_WARN_BYTES:
        options.warn(
            f"basin.csv will be about {format_bytes(csv_bytes)} ({n_points:,} rows); "
            f"--set output.format=npz writes basin.npz instead (about "
            f"{format_bytes(n_points * NPZ_BYTES_PER_ROW)}, read back with "
            "bounce_cli.runtime.artifacts.read_frame), or reduce grid.theta0_deg.num / "
            "grid.v0_m_s.num"
        )
    settings = config.classify.settings()
    outcomes = outcome_names(settings)
    # rows: v0 outer, theta0 inner
    theta_grid_deg, v_grid = np.meshgrid(theta_deg, v0)
    theta_grid_rad = np.deg2rad(theta_grid_deg)

    options.progress.start(n_points, "basin: classifying")
    controller = config.model.controller()
    if controller is not None and settings.min_hop_s == 0.0:
        raise ConfigError("classify.min_hop_s: 0 (exact sticking) is not implemented with "
                          "model.control; give a shortest hop > 0")
    # the passive map, or the racket period controller's map: the same classifier and tiles
    impact_map = (passive_map(params) if controller is None else
                  ControlledMap.of(params, controller, require_fixed_point=True))
    result = classify_map_grid(theta_grid_rad.ravel(), v_grid.ravel(), impact_map, settings,
                               jobs=options.jobs, on_tile_done=options.progress.advance,
                               meanwhile=import_output_libraries)
    import pandas as pd

    from .plotting import caption_figures, control_caption

    basin = pd.DataFrame(
        {
            "theta0_rad": theta_grid_rad.ravel(),
            "theta0_deg": theta_grid_deg.ravel(),
            "v0_m_s": v_grid.ravel(),
            "outcome": pd.Categorical.from_codes(result.outcome, categories=list(outcomes)),
            "iterations": result.iterations,
        }
    )
    del theta_grid_deg, theta_grid_rad, v_grid  # the frame holds copies (large grids)
    counts = np.bincount(result.outcome, minlength=len(outcomes))
    fractions = pd.DataFrame(
        {"outcome": list(outcomes), "count": counts, "fraction": counts / n_points}
    )
    if outcomes is EXACT_OUTCOMES:  # exact sticking: the locked orbit's period
        # empty where it does not apply: the other outcomes, or no orbit locked (resting)
        fractions["period_cycles"] = pd.array(
            [result.locked_cycles if o == "locked" and result.locked_cycles else None
             for o in outcomes], dtype="Int64")
    at_paper = is_passive(controller) and at_paper_parameters(params, settings)
    # Fig. 3's starts also on the exact-sticking basin at the paper's model
    fig3 = at_paper or (outcomes is EXACT_OUTCOMES and is_passive(controller)
                        and paper.at_parameters(params, paper.FIG3_MODEL))
    markers = marker_frame(params, settings, fig3=fig3, controller=controller)

    frames = {table: basin, "fractions.csv": fractions, "markers.csv": markers}
    summary = [
        f"basin: {theta_deg.size} x {v0.size} grid, "
        + ", ".join(f"{o} {f:.4f}" for o, f in zip(outcomes, counts / n_points))
        + (f" (locked: period {result.locked_cycles} racket cycle"
           f"{'s' if result.locked_cycles > 1 else ''}, Lyapunov exponent -inf)"
           if result.locked_cycles else ""),
        f"max impacts until classified: {int(result.iterations.max())} "
        f"(limit {settings.max_iterations}"
        + ("; paper: no point reached 100)" if at_paper else ")"),
    ]
    radius = unstable_radius(markers)
    if radius is not None:
        summary.append(f"no start is period-1: the fixed point is unstable (spectral radius "
                       f"{radius:.3g}, eq. 10), so no orbit stays there; bounce attractors "
                       "finds what the orbits settle on")
    if fig3:
        summary.append("Fig. 3 initial conditions: " + ", ".join(
            f"v0 = {row.v0_m_s:g} m/s -> {row.outcome} after {row.iterations}"
            for row in markers.itertuples() if row.marker != "fixed_point"))
    # each figure drawn by the process that writes it, beside basin.csv (RunDirectory)
    figures = {name: DeferredFigure(functools.partial(draw_one, frames, name))
               for name in FIGURES}
    caption_figures(figures, params, "; ".join(
        t for t in (f"{theta_deg.size} x {v0.size} grid", control_caption(controller)) if t))
    return ExperimentResult(frames=frames, figures=figures, summary=summary)


def classify_map_grid(theta0, v0, impact_map: ImpactMap, settings: ClassifySettings, *,
                      jobs: int, on_tile_done: Callable[[int], None] | None = None,
                      meanwhile: Callable[[], Any] | None = None) -> Classification:
    """``classify_grid`` of any map of the step protocol (the passive map, the controlled
    one) where it runs fastest: the compiled kernel in threads from ``COMPILED_MIN_POINTS``
    points (where the map has one and numba is installed), the numpy kernel on
    ``jobs`` worker processes from ``POOL_MIN_POINTS``, else in this process;
    ``on_tile_done`` as for ``classify_grid``. ``meanwhile`` runs while the grid is
    classified (imports). The result is the same whichever runs it."""
    n_points = np.size(theta0)
    # the compiled kernel releases the GIL: threads, which cost nothing to start
    threads = (n_points >= COMPILED_MIN_POINTS and compiled_kernel_available()
               and has_compiled_kernel(impact_map))
    jobs = jobs if threads or n_points >= POOL_MIN_POINTS else 1
    with parallel.executor(jobs, threads=threads) as executor:
        classify = functools.partial(
            classify_grid, theta0, v0, impact_map, settings,
            map=executor.map, workers=executor.workers, on_tile_done=on_tile_done,
            kernel="compiled" if threads else "numpy",  # decided here, once
        )
        if threads:  # numba's start-up first: it would contend with the imports
            load_compiled_kernel()
        if meanwhile is None:
            return classify()
        # the output's libraries are imported while the grid is classified (in threads
        # or worker processes, or in numpy's loops, which release the GIL)
        return parallel.meanwhile(classify, meanwhile)


def import_output_libraries() -> None:
    """Import what the tables and figures need (pandas, matplotlib and its Agg backend, and
    ``matplotlib.figure`` with its axes, about 0.6 s): done while the compiled kernel
    classifies in threads that do not hold the GIL, so that the import costs no wall time
    on a machine with a core to spare, and before the run directory forks the processes
    that draw the figures (each would import ``matplotlib.figure`` again: 0.1 s). The
    mathtext parser's grammar (the axis labels' ``$\\theta_0$``), which matplotlib builds at
    its first use and keeps for the process, is built here too: 0.03 s once instead of in
    each figure's process (about 0.09 s less CPU time in a 1000 x 1000 run)."""
    with lasting_imports():
        import matplotlib.backends.backend_agg  # noqa: F401
        import matplotlib.figure  # noqa: F401
        import pandas  # noqa: F401
        from matplotlib.mathtext import MathTextParser

        from . import plotting  # noqa: F401

        MathTextParser("agg").parse(r"$\theta_0$")


def format_bytes(n: float) -> str:
    """1234567 -> '1.2 MB' (decimal units, as disk sizes are quoted)."""
    if n < 1000:
        return f"{n:.0f} bytes"
    for unit in ("kB", "MB", "GB"):
        n /= 1000
        if n < 1000 or unit == "GB":
            break
    return f"{n:.1f} {unit}"


def at_paper_parameters(params: ModelParams, settings: ClassifySettings) -> bool:
    """Fig. 4's model (section 3) with section 3's stopping conditions: only there do the
    paper's statements about the basin (and its Fig. 3 initial conditions) apply."""
    return paper.at_parameters(params, paper.FIG3_MODEL) and settings == paper.SECTION3_CLASSIFY


def marker_frame(params: ModelParams, settings: ClassifySettings, *,
                 fig3: bool = True, controller=None) -> pd.DataFrame:
    """The fixed point (eqs. 7, 8) and, with ``fig3``, Fig. 3's two initial conditions (the
    ball on the racket at x_b(0) = 0.205 m, theta0 = asin(x_b(0) / a_r)), each classified
    (with the racket period controller, if any); ``spectral_radius``: the fixed point's
    (eq. 10) on every row for the passive map (where it is unstable no start is
    ``period1``: ``classify.passive_map``), NaN with a controller."""
    fp = params.fixed_point()
    starts = paper.FIG3_V0_M_S if fig3 else {}
    names = ["fixed_point", *starts]
    theta0 = math.asin(paper.FIG3_BALL_HEIGHT_M / params.racket_amplitude) if fig3 else 0.0
    theta = np.array([fp.theta_rad] + [theta0] * len(starts))
    v = np.array([fp.v_m_s, *starts.values()])
    import pandas as pd

    if controller is None:  # three points: numpy (no need to load the compiled kernel)
        res = classify_batch(theta, v, params, settings, kernel="numpy")
        radius = stability(params).spectral_radius
    else:
        from ..analysis.control_design import classify_controlled

        res = classify_controlled(theta, v, params, controller, settings)
        radius = math.nan  # the controlled map keeps its target (its own 3 x 3 stability)
    return pd.DataFrame(
        {
            "marker": names,
            "theta0_deg": np.degrees(theta),
            "v0_m_s": v,
            "outcome": res.names(),
            "iterations": res.iterations,
            "spectral_radius": radius,
        }
    )


#: figures show at most this many cells per axis (every k-th grid point beyond: a 150 dpi
#: figure has ~1100 pixels across, so more cells are invisible and only cost memory)
MAX_IMAGE_CELLS = 1200


class _Grid:
    """Where each row of basin.csv sits on its (v0, theta0) grid. ``image(values)`` -> array
    [v0 index, theta0 index], subsampled to at most MAX_IMAGE_CELLS per axis; ``extent`` for
    imshow. Rows in the order ``run`` writes them (v0 outer, theta0 inner) are reshaped
    without index arrays, so that 10^7-row grids stay cheap; other orders are scattered."""

    def __init__(self, basin: pd.DataFrame) -> None:
        theta, v = basin["theta0_deg"].to_numpy(), basin["v0_m_s"].to_numpy()
        found = _canonical_axes(theta, v)
        if found is not None:  # without sorting 10^6 values twice (0.1 s)
            th, vs = found
            self.index = None
        else:
            th, vs = np.unique(theta), np.unique(v)
            self.index = (np.searchsorted(vs, v), np.searchsorted(th, theta))
        self.shape = (vs.size, th.size)
        self.extent = cell_extent(th, vs)
        self.stride = tuple(-(-n // MAX_IMAGE_CELLS) for n in self.shape)

    def image(self, values, fill=0):
        values = np.asarray(values)
        if self.index is None:
            out = values.reshape(self.shape)
        else:
            out = np.full(self.shape, fill, dtype=values.dtype)
            out[self.index] = values
        return out[:: self.stride[0], :: self.stride[1]]


def _canonical_axes(theta: np.ndarray, v: np.ndarray):
    """(theta values, v values) when the rows are in ``run``'s order -- v0 outer, theta0
    inner, both strictly increasing, every combination once -- else None."""
    if theta.size == 0:
        return None
    changes = np.flatnonzero(v != v[0])
    n_theta = int(changes[0]) if changes.size else v.size
    if v.size % n_theta:
        return None
    th, vs = theta[:n_theta], v[::n_theta]
    shape = (vs.size, n_theta)
    if (np.all(np.diff(th) > 0) and np.all(np.diff(vs) > 0)
            and (theta.reshape(shape) == th).all() and (v.reshape(shape) == vs[:, None]).all()):
        return th, vs
    return None


def _draw_markers(ax, markers: pd.DataFrame, extent) -> None:
    x0, x1, y0, y1 = extent
    inside = markers[
        markers.theta0_deg.between(x0, x1) & markers.v0_m_s.between(y0, y1)
    ]
    for row in inside.itertuples():
        if row.marker == "fixed_point":
            ax.plot(row.theta0_deg, row.v0_m_s, "o", ms=7, mfc="black", mec="white",
                    label="period-1 fixed point (eqs. 7, 8)")
        else:
            ax.plot(row.theta0_deg, row.v0_m_s, "X", ms=9, mfc="black", mec="white",
                    label=f"Fig. 3: $v_0$ = {row.v0_m_s:g} m/s ({row.outcome})")


def basin_table(frames: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """The grid's table among a run's frames, whatever its format (``BASIN_TABLES``)."""
    for name in BASIN_TABLES.values():
        if name in frames:
            return frames[name]
    raise KeyError("basin.csv")


#: the run's figures, in the order ``draw`` makes them
FIGURES = ("basin.png", "basin_iterations.png")


def draw_one(frames: dict[str, pd.DataFrame], name: str):
    """The figure ``name`` (one of :data:`FIGURES`) alone, as ``draw`` makes it."""
    return draw(frames, only=(name,))[name]


@publication_style
def draw(frames: dict[str, pd.DataFrame], only: Collection[str] = FIGURES) -> dict:
    """basin.png and basin_iterations.png (those of them named in ``only``), from basin.csv
    (or basin.npz / basin.parquet) and markers.csv only."""
    import pandas as pd

    basin, markers = basin_table(frames), frames["markers.csv"]
    codes = pd.Categorical(basin["outcome"], categories=list(EXACT_OUTCOMES)).codes
    fractions = frames.get("fractions.csv")
    exact = fractions is not None and "period_cycles" in fractions
    shown = [o for i, o in enumerate(EXACT_OUTCOMES) if o in OUTCOMES or (codes == i).any()]
    labels = dict(OUTCOME_LABELS)
    if exact and fractions is not None:
        cycles = fractions.period_cycles.max()  # NaN (or NA): no orbit locked
        if pd.notna(cycles):
            cycles = int(cycles)
            labels["locked"] += f", period {cycles} racket cycle{'s' if cycles != 1 else ''}"
        labels["undecided"] = "undecided in max impacts (chaotic or a long transient)"
    radius = unstable_radius(markers)
    title = "Domain of attraction of the period-1 attractor (paper Fig. 4)"
    if radius is not None:
        labels["period1"] = "period-1: none (unstable)"
        title = (f"Outcomes of the starts: no period-1 attractor\n(the fixed point is "
                 f"unstable, spectral radius {radius:.3g}, eq. 10)")
    grid = _Grid(basin)
    figures = {}
    if "basin.png" in only:
        figures["basin.png"] = _outcome_figure(grid, codes, markers, shown, labels, exact,
                                               title)
    if "basin_iterations.png" in only:
        figures["basin_iterations.png"] = _iterations_figure(grid, codes, basin, markers,
                                                             exact)
    return figures


def unstable_radius(markers: pd.DataFrame) -> float | None:
    """The fixed point's spectral radius where markers.csv records it as unstable (eq. 10,
    ``linear.is_stable``), else None (stable, a controller, or a table without it)."""
    if "spectral_radius" not in markers or markers.empty:
        return None
    radius = float(markers["spectral_radius"].iloc[0])
    return radius if math.isfinite(radius) and not is_stable(radius) else None


def _outcome_figure(grid: _Grid, codes, markers: pd.DataFrame, shown: list[str],
                    labels: dict[str, str], exact: bool, title: str):
    """basin.png: each start's outcome (Fig. 4's white, grey and black), with the markers."""
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    from .plotting import new_figure

    image, extent = grid.image(codes), grid.extent
    fig, axes = new_figure(width=7.5, height=6.2)
    ax = axes[0, 0]
    cmap = ListedColormap([OUTCOME_COLOURS[o] for o in EXACT_OUTCOMES])
    norm = BoundaryNorm(np.arange(len(EXACT_OUTCOMES) + 1) - 0.5, cmap.N)
    # the cells' colours as bytes (the pixels the colormap gives, cmap(norm(code))): the
    # renderer then resamples bytes, not an array of floats (0.06 s less a figure)
    ax.imshow(cell_colours(image, lambda codes: cmap(norm(codes), bytes=True)), origin="lower",
              extent=extent, aspect="auto", interpolation="nearest")
    _draw_markers(ax, markers, extent)
    handles = [Patch(facecolor=OUTCOME_COLOURS[o], edgecolor="0.3", label=labels[o])
               for o in shown if not (exact and o == "sticking")]
    handles += ax.get_legend_handles_labels()[0]
    fig.legend(handles=handles, **(LEGEND_BELOW | {"ncol": 2} if exact else LEGEND_BELOW))
    ax.set_xlabel(r"initial phase $\theta_0$ (deg)")
    ax.set_ylabel(r"initial velocity $v_0$ (m/s)")
    ax.set_title(title + (",\nexact sticking (min_hop_s 0)" if exact else ""))
    return fig


def _iterations_figure(grid: _Grid, codes, basin: pd.DataFrame, markers: pd.DataFrame,
                       exact: bool):
    """basin_iterations.png: the impacts until each start was classified."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.patches import Patch

    from .plotting import integer_axis, new_figure

    extent = grid.extent
    iters = grid.image(basin["iterations"].to_numpy())
    below = grid.image(codes == OUTCOMES.index("below_racket")).astype(bool)
    fig2, axes2 = new_figure(width=7.5, height=6.2)
    ax2 = axes2[0, 0]
    # as bytes, as above: the colour bar's mappable (of the same colormap and range) stands
    # for the image; the cells below the racket transparent (the colormap's colour of a
    # masked value), the axes' black behind
    counts = iters[~below]
    low, high = (float(counts.min()), float(counts.max())) if counts.size else (0.0, 0.0)
    # one count everywhere (or none: every start below the racket): the bar spans that
    # count +- 1/2, its middle colour (as imshow draws a constant image), one tick
    one = low == high
    scale = ScalarMappable(Normalize(low - 0.5 * one, high + 0.5 * one), colormaps["viridis"])
    cells = cell_colours(iters, lambda n: scale.to_rgba(n.astype(float), bytes=True))
    cells[below] = scale.to_rgba(np.ma.masked_array([0.0], mask=[True]), bytes=True)[0]
    ax2.imshow(cells, origin="lower", extent=extent, aspect="auto", interpolation="nearest")
    ax2.set_facecolor("black")
    bar = fig2.colorbar(scale, ax=ax2, label="impacts until classified")
    if one:
        bar.set_ticks([low])
    else:
        integer_axis(bar.ax, which="y")
    _draw_markers(ax2, markers, extent)
    fig2.legend(
        handles=[Patch(facecolor="black", label="below the racket")]
        + ax2.get_legend_handles_labels()[0],
        **LEGEND_BELOW,
    )
    ax2.set_xlabel(r"initial phase $\theta_0$ (deg)")
    ax2.set_ylabel(r"initial velocity $v_0$ (m/s)")
    ax2.set_title("Impacts until classified (paper Fig. 4, section 3)"
                  + (",\nexact sticking (min_hop_s 0)" if exact else ""))
    return fig2


EXPERIMENT = Experiment(name="basin", schema=BasinConfig, run=run, draw=draw)
