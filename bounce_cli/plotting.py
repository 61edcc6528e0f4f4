"""Figure helpers shared by the experiments: figures are built on matplotlib's object API
(no pyplot state, no display needed) from the same DataFrames that are written as CSV."""

from __future__ import annotations

from matplotlib.figure import Figure


def new_figure(nrows: int = 1, ncols: int = 1, *, width: float = 6.4, height: float = 4.8,
               **subplot_kw):
    """A Figure with a grid of axes (``squeeze=False`` so ``axes[i, j]`` always works)."""
    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **subplot_kw)
    return fig, axes


def paper_caption(fig: Figure, text: str) -> None:
    """A small caption under the figure naming the paper figure and parameters."""
    fig.text(0.5, 0.0, text, ha="center", va="bottom", fontsize=7, color="0.35")
