"""Shared test helpers: the CLI runner, the one-line-error assertion and the paper's parameter
sets, as fixtures (test modules never import from one another)."""

import os
import signal
import subprocess

import matplotlib
import pytest

matplotlib.use("Agg")

from typer.testing import CliRunner  # noqa: E402

from bounce_cli.paper import values as paper  # noqa: E402
from bounce_cli.cli.commands import app  # noqa: E402
from bounce_cli.model.params import ModelParams  # noqa: E402

_runner = CliRunner()


def run_cli(*args):
    """``bounce ARGS`` in-process (typer's CliRunner); arguments are stringified."""
    return _runner.invoke(app, [str(a) for a in args])


def assert_one_line_error(result, *needles):
    """Exit 2, exactly one ``bounce: error: ...`` line on stderr (an instability warning may
    precede it) holding every needle, and no traceback."""
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines()
             if line.strip() and not line.startswith("bounce: warning: ")]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("bounce: error: "), lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert "Traceback" not in result.output


@pytest.fixture(scope="session")
def cli():
    """The CLI runner: ``cli("basin", "--quiet", ...)`` -> click Result."""
    return run_cli


@pytest.fixture(scope="session")
def user_error():
    """The one-line user error assertion: ``user_error(result, "needle", ...)``."""
    return assert_one_line_error


def layout_problems(fig, dpi: float = 150) -> list[str]:
    """What a reader would see cut off or covered in ``fig`` drawn as a PNG at ``dpi``: a
    title, axis label, legend entry or annotation reaching outside the figure, a title
    under a legend, or neighbouring tick labels less than 2 pixels apart. Empty where the
    figure is laid out."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    fig.dpi = dpi
    canvas.draw()  # the layout engine runs as part of the draw
    renderer = canvas.get_renderer()
    width, height = fig.bbox.width, fig.bbox.height
    titles = [t for ax in fig.axes for t in (ax.title, ax._left_title, ax._right_title)]
    if fig._suptitle is not None:
        titles.append(fig._suptitle)
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes)]
    legends = [lg for lg in legends if lg is not None and lg.get_visible()]
    texts = [*titles, *(ax.xaxis.label for ax in fig.axes), *(ax.yaxis.label for ax in fig.axes),
             *(t for ax in fig.axes for t in ax.texts), *fig.texts,
             *(t for lg in legends for t in lg.get_texts())]
    problems = []
    for text in texts:
        if not (text.get_visible() and text.get_text().strip()):
            continue
        box = text.get_window_extent(renderer)
        if box.x0 < -1 or box.y0 < -1 or box.x1 > width + 1 or box.y1 > height + 1:
            problems.append(f"{text.get_text()!r} reaches outside the figure")
    for title in titles:
        if not (title.get_visible() and title.get_text().strip()):
            continue
        box = title.get_window_extent(renderer)
        for legend in legends:
            if box.overlaps(legend.get_window_extent(renderer)):
                problems.append(f"the title {title.get_text()!r} is under a legend")
    for ax in fig.axes:  # tick labels running into each other ("-1.00-0.75-0.50")
        if ax.name != "rectilinear":  # a 3-d or polar axis lays its labels out otherwise
            continue
        for axis, lo, hi in ((ax.xaxis, "x0", "x1"), (ax.yaxis, "y0", "y1")):
            low, high = sorted(axis.get_view_interval())
            labels = [tick.label1 for tick in axis.get_major_ticks()
                      if tick.label1.get_visible() and tick.label1.get_text()
                      and low - 1e-9 * (high - low) <= tick.get_loc() <= high + 1e-9 * (
                          high - low)]
            boxes = sorted(((t.get_window_extent(renderer), t.get_text()) for t in labels),
                           key=lambda item: getattr(item[0], lo))
            for (a, text_a), (b, text_b) in zip(boxes, boxes[1:]):
                if getattr(b, lo) < getattr(a, hi) + 2.0:  # less than 2 pixels apart
                    problems.append(f"tick labels {text_a!r} and {text_b!r} run together")
    return problems


@pytest.fixture(scope="session")
def figure_layout_problems():
    return layout_problems


@pytest.fixture(scope="session")
def paper_params() -> ModelParams:
    """The paper's Figs. 3-4 and 9 parameters (sections 3, 7)."""
    return paper.FIG3_MODEL


@pytest.fixture(scope="session")
def acf_params() -> ModelParams:
    """The paper's Fig. 8 parameters (section 6)."""
    return paper.FIG8_MODEL


@pytest.fixture(autouse=True)
def _no_color(monkeypatch):
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("COLUMNS", "200")
    yield


def pytest_configure(config):
    os.environ.setdefault("MPLBACKEND", "Agg")


#: the environment of a bounce process a test may find hung: faulthandler dumps every thread's
#: stack on SIGABRT (``ended_or_stacks``)
DUMPABLE = {**os.environ, "PYTHONFAULTHANDLER": "1"}


def ended_or_stacks(process: subprocess.Popen, timeout: float, what: str) -> tuple[str, str]:
    """``process.communicate(timeout)``; a process still running then (started with
    ``env=DUMPABLE``, in a session of its own) fails the test with where each of its threads
    was: SIGABRT (faulthandler's dump on stderr), and SIGKILL to its group after 10 s more
    (a child holding the pipe open)."""
    try:
        return process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        pass
    process.send_signal(signal.SIGABRT)
    try:
        _, err = process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        _, err = process.communicate()
    pytest.fail(f"{what}: still running after {timeout:g} s; its threads were at:\n{err}")


@pytest.fixture(scope="session")
def ended():
    """``ended(process, timeout, what)`` -> (stdout, stderr) of a process that ended within
    ``timeout`` s; else the test fails with its threads' stacks (``ended_or_stacks``)."""
    return ended_or_stacks


@pytest.fixture(scope="session")
def dumpable_env():
    """The environment for a process ``ended`` may have to dump."""
    return DUMPABLE
