import os

import matplotlib
import pytest

matplotlib.use("Agg")

from bounce_cli.engine import ModelParams  # noqa: E402


@pytest.fixture
def paper_params() -> ModelParams:
    """The paper's Figs. 3-4 and 9 parameters (section 3)."""
    return ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)


@pytest.fixture(autouse=True)
def _no_color(monkeypatch):
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("COLUMNS", "200")
    yield


def pytest_configure(config):
    os.environ.setdefault("MPLBACKEND", "Agg")
