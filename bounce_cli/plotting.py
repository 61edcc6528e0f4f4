"""Figure helpers shared by the experiments: figures are built on matplotlib's object API
(no pyplot state, no display needed) from the same DataFrames that are written as CSV."""

from __future__ import annotations

from typing import Any

from matplotlib.figure import Figure

from .engine.params import ModelParams
from .paper import parameters_text


def new_figure(nrows: int = 1, ncols: int = 1, *, width: float = 6.4, height: float = 4.8,
               **subplot_kw: Any) -> tuple[Figure, Any]:
    """A Figure with a grid of axes (``squeeze=False`` so ``axes[i, j]`` always works)."""
    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **subplot_kw)
    return fig, axes


def caption_figures(figures: dict[str, Figure], params: ModelParams | None,
                    extra: str = "") -> None:
    """Add the parameters a run was made at (and ``extra``, e.g. the run's size and seed) as
    the last line of each figure's title, so that figures of two runs can be told apart."""
    parts = ([parameters_text(params)] if params is not None else []) + ([extra] if extra else [])
    if not parts:
        return
    line = "; ".join(parts)
    for fig in figures.values():
        title = fig.get_suptitle()
        fig.suptitle(f"{title}\n{line}" if title else line,
                     fontsize=10 if title else 9)


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
