"""Figure files: a figure written as PNG, PDF or SVG with its title, caption and source in the
file's metadata (the PNG's text chunks, the PDF's document information, SVG's Dublin Core),
and no date, so that a rerun writes the same bytes. The run directory writes every figure
through :func:`save_figure`."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Callable, Iterator

if TYPE_CHECKING:  # matplotlib is imported when a figure is written
    from matplotlib.figure import Figure

#: the file formats a figure can be written in (``--figure-format``)
FIGURE_FORMATS = ("png", "pdf", "svg")
#: resolution of the PNG figures unless ``--dpi`` says otherwise
FIGURE_DPI = 150

#: rcParams while a figure is written: fonts embedded as TrueType in PDF (editable, accepted
#: by journals; matplotlib's default Type 3 is not), SVG element ids from a fixed salt (a
#: rerun writes the same bytes)
SAVE_STYLE: dict[str, Any] = {"pdf.fonttype": 42, "svg.hashsalt": "bounce"}

#: a figure's attribute holding its caption line (parameters, run size, seed, data), set by
#: :func:`bounce_cli.experiments.plotting.caption_figures`
CAPTION_ATTRIBUTE = "_bounce_caption"


def figure_caption(fig: Figure) -> str:
    """The caption line ``plotting.caption_figures`` recorded ('' for a figure drawn from CSVs)."""
    return str(getattr(fig, CAPTION_ATTRIBUTE, ""))


def figure_title(fig: Figure) -> str:
    """The figure's title: its suptitle, else its first axes title (one line)."""
    title = fig.get_suptitle() or next((ax.get_title() for ax in fig.axes if ax.get_title()),
                                       "")
    return " ".join(title.split())


def figure_metadata(fig: Figure, kind: str, source: str) -> dict[str, Any]:
    """The metadata written into a figure file of format ``kind``: its title, its caption
    (``plotting.caption_figures``) and the command that made it (``source``); no date, so that a
    rerun writes the same bytes. Keys as each format names them (PNG text chunks, the PDF
    document information, SVG's Dublin Core)."""
    title, caption = figure_title(fig), figure_caption(fig)
    meta: dict[str, Any]
    if kind == "png":
        meta = {"Title": title, "Description": caption, "Source": source}
    elif kind == "pdf":
        meta = {"Title": title, "Subject": caption, "Creator": source, "CreationDate": None}
    else:
        meta = {"Title": title, "Description": caption, "Creator": source, "Date": None}
    return {k: encodable(v) for k, v in meta.items() if v != ""}


def encodable(value: Any) -> Any:
    """A metadata text that UTF-8 can encode: a path the command line could not decode (its
    bytes kept as surrogates, e.g. under ``LC_ALL=C`` without UTF-8 mode, or a file name in
    another encoding) is decoded as UTF-8 again, a byte that is not UTF-8 shown as U+FFFD;
    other values unchanged.

    Parameters
    ----------
    value : str or None
        A title, caption or source.

    Returns
    -------
    str or None
    """
    if not isinstance(value, str):
        return value
    return value.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


class DeferredFigure:
    """A figure drawn when it is first needed: where it is written.

    An experiment may hand its figures to the run as ``DeferredFigure(draw)``, ``draw`` a
    function of no arguments returning the Figure. A run directory writes half of a run's
    figures in a child process (``RunDirectory.commit``): a deferred figure is then drawn in
    the process that writes it, beside the other files, instead of before any is written;
    and a rerun that keeps its figures (``bounce reproduce`` with every table unchanged)
    never draws them. A caption set on it (``plotting.caption_figures``) goes onto the
    figure. Drawn once per process: :meth:`figure` returns the same Figure afterwards."""

    def __init__(self, draw: Callable[[], Figure]) -> None:
        self._draw = draw
        self._figure: Figure | None = None

    def figure(self) -> Figure:
        """The figure, drawn on the first call."""
        if self._figure is None:
            figure = self._draw()
            caption = getattr(self, CAPTION_ATTRIBUTE, None)
            if caption is not None:
                setattr(figure, CAPTION_ATTRIBUTE, caption)
            self._figure = figure
        return self._figure


def drawn(figure: Figure | DeferredFigure) -> Figure:
    """The Figure itself: a :class:`DeferredFigure` drawn (once), any other returned as it is."""
    return figure.figure() if isinstance(figure, DeferredFigure) else figure


def save_figure(fig: Figure | DeferredFigure, path: Path | BinaryIO, kind: str, *, dpi: float,
                source: str, png_options: dict[str, Any] | None = None) -> None:
    """Write ``fig`` to ``path`` as ``kind`` (one of :data:`FIGURE_FORMATS`) at ``dpi``, with
    :func:`figure_metadata`, in :data:`SAVE_STYLE`.

    Parameters
    ----------
    fig : Figure or DeferredFigure
        The figure (from an experiment's ``draw``); a deferred one is drawn here.
    path : Path or binary file object
        The file to write (its name's suffix is not consulted).
    kind : str
        "png", "pdf" or "svg".
    dpi : float
        Resolution of a PNG (and of raster parts of a PDF or SVG), dots per inch.
    source : str
        What made the figure (e.g. ``bounce basin``), written into its metadata.
    png_options : dict, optional
        Pillow's options for a PNG (e.g. ``{"compress_level": 1}``).

    Returns
    -------
    None
    """
    from matplotlib import rc_context

    fig = drawn(fig)
    extra: dict[str, Any] = {"pil_kwargs": png_options} if kind == "png" and png_options else {}
    with rc_context(SAVE_STYLE), laid_out(fig, kind, dpi):  # type: ignore[arg-type]
        fig.savefig(path, format=kind, dpi=dpi, metadata=figure_metadata(fig, kind, source),
                    **extra)


@contextlib.contextmanager
def laid_out(fig: Figure, kind: str, dpi: float) -> Iterator[None]:
    """A PNG's layout done before ``savefig``, which then draws the figure once.

    ``savefig`` of a figure with any layout engine (``constrained``, or the place holder
    that ``set_layout_engine("none")`` leaves) first draws the whole figure without output,
    to run the engine in the course of it, and then draws it again: the first draw resamples
    every image and lays out every text once more (about a quarter of the 1000 x 1000
    basin's figures). Here the engine runs alone, with the renderer ``savefig`` would give
    it (Agg at ``dpi``: the same text metrics, hence the same layout and the same bytes,
    which a test compares), and the figure has no engine at all while it is saved (``savefig``
    sets its engine aside after its first draw). Only PNG (Agg): a vector format measures
    text with its own renderer. The figure's canvas, resolution and engine are restored
    afterwards."""
    engine = fig.get_layout_engine()
    if kind != "png" or engine is None:
        yield
        return
    from matplotlib import rc_context
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas, figure_dpi = fig.canvas, fig.dpi
    try:
        FigureCanvasAgg(fig)  # the figure's canvas while it is laid out
        fig.dpi = dpi
        engine.execute(fig)
        with rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)  # no engine: savefig draws once
        yield
    finally:
        fig.set_layout_engine(engine)
        fig.dpi = figure_dpi
        fig.set_canvas(canvas)
