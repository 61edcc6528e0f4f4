"""Figure helpers shared by the experiments: figures are built on matplotlib's object API
(no pyplot state, no display needed) from the same DataFrames that are written as CSV.

The publication style is written here once and applied by every experiment's ``draw``
(:func:`publication_style`): mathtext for every symbol (``$\\theta_k$``, ``m/s$^2$``, never
``theta[k]`` or ``m/s^2``), integer ticks on integer axes (:func:`integer_axis`: trial,
impact index, lag), and no run metadata in titles: the parameters, size and seed of a run
(:func:`caption_figures`) go into the file's metadata instead (the PNG's text chunks, the
PDF's Subject, the SVG's Description; :func:`bounce_cli.runtime.figure_files.save_figure`),
beside ``run.json``.
"""

from __future__ import annotations

import functools
import math
import re
from typing import TYPE_CHECKING, Any, Callable, Mapping, TypeVar

import numpy as np

from ..paper.values import parameters_text
from ..runtime.figure_files import CAPTION_ATTRIBUTE, DeferredFigure

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn (an experiment's module
    # can be imported, and its draw decorated, without it)
    import pandas as pd
    from matplotlib.figure import Figure

    from ..model.params import ModelParams

#: rcParams of every figure while it is drawn: an axis's offset and power of ten in mathtext
#: (superscripts: x10^-3, not 1e-3); its tick labels are plain text all the same
#: (:func:`plain_tick_labels`), with a true minus sign (``axes.unicode_minus``)
DRAW_STYLE: dict[str, Any] = {"axes.formatter.use_mathtext": True}

#: how ``ScalarFormatter`` wraps a tick label in mathtext under ``use_mathtext``
_MATHTEXT_TICK = re.compile(r"\$\\mathdefault\{([^\\{}$]*)\}\$")

#: axis labels of the responses to a perturbation (Figs. 9-11: impulse, its data side, control)
VELOCITY_LABEL = "velocity after impact $v_k$ (m/s)"
PHASE_LABEL = r"phase of impact $\theta_k$ (deg)"
IMPACT_AFTER_LABEL = "impact $k$ after the perturbation (0: the perturbed impact)"
#: the same in two lines, under panels narrower than it (three across a page)
IMPACT_AFTER_LABEL_NARROW = IMPACT_AFTER_LABEL.replace(" (0:", "\n(0:")

F = TypeVar("F", bound=Callable[..., Any])


def publication_style(draw: F) -> F:
    """Decorator of an experiment's ``draw``: its figures are made in :data:`DRAW_STYLE`."""

    @functools.wraps(draw)
    def styled(*args, **kwargs):
        from matplotlib import rc_context

        with rc_context(DRAW_STYLE):  # type: ignore[arg-type]  # (the keys are rcParams)
            figures = draw(*args, **kwargs)
        for fig in figures.values():
            plain_tick_labels(fig)
        return figures

    return styled  # type: ignore[return-value]


def plain_tick_labels(fig: Figure) -> None:
    """Tick labels of ``fig``'s linear axes as plain text: the same digits and true minus sign
    as mathtext's ``\\mathdefault`` in the same font, without its parser (about a quarter of the
    time a study spent writing its figures went into parsing tick labels as mathtext). An axis's
    offset text (x10^k) stays mathtext; log axes (10^k tick labels) are left alone."""
    from matplotlib.ticker import ScalarFormatter

    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            formatter = axis.get_major_formatter()
            if type(formatter) is ScalarFormatter:  # not a subclass with labels of its own
                formatter.__class__ = _plain_tick_formatter()  # its settings kept


@functools.cache
def _plain_tick_formatter():
    """``ScalarFormatter`` with its tick labels unwrapped from ``$\\mathdefault{...}$``."""
    from matplotlib.ticker import ScalarFormatter

    class PlainTickFormatter(ScalarFormatter):
        def __call__(self, x, pos=None):
            label = super().__call__(x, pos)
            match = _MATHTEXT_TICK.fullmatch(label)
            return label if match is None else match.group(1)

    return PlainTickFormatter


def new_figure(nrows: int = 1, ncols: int = 1, *, width: float = 6.4, height: float = 4.8,
               **subplot_kw: Any) -> tuple[Figure, Any]:
    """A Figure with a grid of axes (``squeeze=False`` so ``axes[i, j]`` always works)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **subplot_kw)
    return fig, axes


def sweep_figure(column: str) -> tuple[Figure, Any, Any]:
    """The two panels over a swept parameter (bifurcation.png, continuation.png): a tall top
    one above a short bottom one on the same x axis, labelled with the parameter whose values
    are the table column ``column`` (a key of
    :data:`bounce_cli.analysis.bifurcation.SWEEPABLE`). Returns (figure, top, bottom)."""
    from ..analysis.bifurcation import SWEEPABLE

    parameter = next(p for p, (col, _) in SWEEPABLE.items() if col == column)
    fig, axes = new_figure(2, 1, width=8.0, height=7.5, sharex=True,
                           gridspec_kw=dict(height_ratios=[2.2, 1]))
    top, bottom = axes[0, 0], axes[1, 0]
    bottom.set_xlabel(SWEEPABLE[parameter][1])
    return fig, top, bottom


def perturbation_title(lower: bool) -> str:
    """The title of a column of Figs. 9-11: the perturbed alpha below or above alpha_0."""
    return r"$\alpha_p < \alpha_0$" if lower else r"$\alpha_p > \alpha_0$"


def integer_axis(*axes: Any, which: str = "x") -> None:
    """Ticks at whole numbers only on the ``which`` axis ("x", "y" or a colorbar's "y") of
    each of ``axes``: a trial, an impact index or a lag has no value 1.25."""
    from matplotlib.ticker import MaxNLocator

    for ax in axes:
        getattr(ax, f"{which}axis").set_major_locator(MaxNLocator(integer=True))


def caption_figures(figures: Mapping[str, Figure | DeferredFigure],
                    params: ModelParams | None, extra: str = "") -> None:
    """Record the parameters a run was made at (and ``extra``, e.g. the run's size and seed)
    as each figure's caption (a deferred figure's: set on the figure once drawn): written
    into the file's metadata (``figure_files.save_figure``), not into its title, so that
    figures of two runs can be told apart without the title carrying run metadata."""
    parts = ([parameters_text(params)] if params is not None else []) + ([extra] if extra else [])
    for fig in figures.values():
        setattr(fig, CAPTION_ATTRIBUTE, "; ".join(parts))


def control_caption(controller: Any) -> str:
    """A caption's words for the racket period controller (``model.control``), '' for the
    passive map (None)."""
    return ("" if controller is None else
            f"racket period control K = {controller.gain:g}, c = {controller.rate:g}")


def data_caption(config: Any, source: Any = None, record: dict | None = None) -> str:
    """A data-side figure's caption line: where the impacts came from and the model's alpha
    and g with their sources (``record``: a run's ``RunOptions.record``, whose
    ``model_at_data`` the data analyses fill; else the config's; the racket is the data's)."""
    if source is not None:
        where = "data: a simulated lab session"
    elif config.data is not None:
        where = "data: " + " + ".join(
            [str(p) for p in config.data] if isinstance(config.data, list) else [config.data])
    else:
        where = "model only (no --data)"
    used = (record or {}).get("model_at_data")
    if used:
        alpha, g = used["alpha"], used["g"]
        return (f"{where}; model alpha = {alpha['value']:.3g} ({alpha['source']}), "
                f"g = {g['value']:.3g} m/s^2 ({g['source']})")
    return f"{where}; model alpha = {config.model.alpha:g}, g = {config.model.g:g} m/s^2"


#: panel layout of Fig. 8: (row, column) -> pair
PANELS = {(0, 0): "v_v", (0, 1): "theta_to_v", (1, 0): "v_to_theta", (1, 1): "theta_theta"}
TITLES = {
    "v_v": r"ACF of velocity: corr($v_{k+l}$, $v_k$)",
    "theta_to_v": r"phase $\to$ velocity: corr($v_{k+l}$, $\theta_k$)",
    "v_to_theta": r"velocity $\to$ phase: corr($\theta_{k+l}$, $v_k$)",
    "theta_theta": r"ACF of phase: corr($\theta_{k+l}$, $\theta_k$)",
}
#: the x axis of every correlation panel (Fig. 8, with data, with control)
LAG_LABEL = "lag $l$ (bounces)"


def finish_correlation_panel(ax: Any, pair: str, bottom: bool) -> None:
    """Dress one panel of Fig. 8 (model or data): the correlation's range and label, the
    pair's title, whole lags, and the lag label on the ``bottom`` row."""
    ax.set_ylim(-1.05, 1.05)
    ax.set_title(TITLES[pair], fontsize=10)
    ax.set_ylabel("correlation")
    integer_axis(ax)
    if bottom:
        ax.set_xlabel(LAG_LABEL)


def cell_extent(x, y) -> tuple[float, float, float, float]:
    """imshow's ``extent`` for an image whose cells are centred on the sorted, evenly spaced
    grid values ``x`` (columns) and ``y`` (rows): half a cell beyond the first and last value
    on each axis. An axis of one value is drawn one unit (deg, m/s) wide, centred on it."""
    def half(values) -> float:
        values = np.asarray(values, dtype=float)
        return 0.5 * (float(values[-1] - values[0]) / (values.size - 1) if values.size > 1
                      else 1.0)

    hx, hy = half(x), half(y)
    return (float(x[0]) - hx, float(x[-1]) + hx, float(y[0]) - hy, float(y[-1]) + hy)


#: at most this many distinct integers are coloured through a table (``cell_colours``)
CELL_COLOUR_TABLE_MAX = 1 << 16


def cell_colours(values: np.ndarray, colour: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``colour(values)`` (the RGBA bytes of each cell, e.g. a colormap of a norm) of an
    integer array, through a table of the colours of ``values``' range: a colormap and a norm
    map each value on its own, so the table gives the same bytes, without the float arrays
    of the whole grid (a 1000 x 1000 basin figure: 0.02-0.05 s less a figure). Values
    spanning more than ``CELL_COLOUR_TABLE_MAX`` are coloured directly."""
    values = np.asarray(values)
    if values.size == 0 or values.dtype.kind not in "iu":
        return colour(values)
    low, high = int(values.min()), int(values.max())
    if high - low >= CELL_COLOUR_TABLE_MAX:
        return colour(values)
    table = colour(np.arange(low, high + 1).astype(values.dtype))
    index = np.subtract(values, low, dtype=np.intp) if low else values
    if table.dtype != np.uint8 or table.shape[-1] != 4:
        return table[index]
    # each cell's four bytes as one 32-bit word: one gather instead of four (10 x faster)
    words = np.ascontiguousarray(table).view(np.uint32).ravel()
    return words[index].view(np.uint8).reshape(*values.shape, 4)


def centred_deg(theta_deg):
    """Phases in degrees mapped to [-180, 180): means and plots of phases near 0 stay
    meaningful (the table keeps [0, 360))."""
    return (np.asarray(theta_deg, dtype=float) + 180.0) % 360.0 - 180.0


# -- Fig. 2 -------------------------------------------------------------------------------------
#: Fig. 2's v_k and theta_k panels span at least +- this around their mean (m/s, deg): a
#: session whose impacts vary by rounding only (the virtual set-up's sine racket: 5e-8 m/s)
#: shows a flat line
FIG2_MIN_SPAN = {"v_m_s": 0.01, "theta_deg": 0.5}


def draw_fig2(samples: pd.DataFrame, impacts: pd.DataFrame, title: str, bounces: int = 10):
    """Fig. 2: continuous trajectories on top; v_k and theta_k of the same bounces below, each
    with its sample mean dashed. Shows the first trial of ``samples``, its impacts within the
    samples' time span (at most ``bounces``); perturbed impacts (if marked) in red. ``{shown}``
    in ``title`` says which: "the first 10 bounces", or "the trial's 8 bounces" where it has
    fewer."""
    label = samples["trial"].iloc[0]
    s = samples[samples["trial"].astype(str) == str(label)]
    t0, t1 = float(s["t_s"].min()), float(s["t_s"].max())
    imp = impacts[(impacts["trial"].astype(str) == str(label)) & (impacts["t_s"] >= t0)
                  & (impacts["t_s"] <= t1)].head(bounces)
    fig, axes = new_figure(3, 1, width=7.5, height=7.0, sharex=True,
                           gridspec_kw={"height_ratios": [2.2, 1, 1]})
    ax_x, ax_v, ax_th = axes[0, 0], axes[1, 0], axes[2, 0]
    if imp.empty:
        t_hi = t1
    else:
        last = imp.iloc[-1]
        t_hi = min(t1, float(last["t_s"]) + (float(last["hop_s"])
                                              if math.isfinite(last["hop_s"]) else 0.0))
    s = s[s["t_s"] <= t_hi]
    ax_x.plot(s["t_s"], s["ball_x_m"], color="C0", lw=1.0, label="ball $x_b$")
    ax_x.plot(s["t_s"], s["racket_x_m"], color="k", lw=0.9, label="racket $x_r$")
    ax_x.set_ylabel("position (m)")
    ax_x.legend(loc="upper right", fontsize=7, ncol=2)
    perturbed = (imp["perturbed"].astype(str).str.lower() == "true").to_numpy() \
        if "perturbed" in imp.columns else np.zeros(len(imp), dtype=bool)
    for ax, column, label_, color in ((ax_v, "v_m_s", "$v_k$ (m/s)", "C0"),
                                      (ax_th, "theta_deg", "$\\theta_k$ (deg)", "C2")):
        t, y = imp["t_s"].to_numpy(float), imp[column].to_numpy(float)
        if column == "theta_deg":
            y = centred_deg(y)
        ax.plot(t, y, "o-", ms=4, lw=0.8, color=color)
        if perturbed.any():
            ax.plot(t[perturbed], y[perturbed], "o", ms=6, color="C3",
                    label=r"perturbed impact ($\alpha$ changed)")
            ax.legend(loc="best", fontsize=7)
        if len(y):
            ax.axhline(float(np.mean(y)), ls="--", color="0.4", lw=0.8)
            span = FIG2_MIN_SPAN[column]
            if np.ptp(y) < span:  # rounding-level variation (the model's own ball) drawn
                # flat, not blown up under an offset label ("x1e-6 + 42.76349")
                ax.set_ylim(float(np.mean(y)) - span, float(np.mean(y)) + span)
        ax.set_ylabel(label_)
        for ti in t:
            ax_x.axvline(ti, color="0.85", lw=0.6, zorder=0)
    ax_th.set_xlabel("time $t$ (s)")
    n = len(imp)
    shown = (f"the first {n} bounces" if n == bounces and n > 1 else
             f"the trial's {n} bounce{'s' if n != 1 else ''}")
    fig.suptitle(f"Fig. 2: {title.format(shown=shown)}\ntrial {label}; dashed: sample means "
                 "of the bounces shown", fontsize=10)
    return fig
