"""One module per paper experiment: config -> tidy DataFrames (+ figures drawn from them)."""

from .base import Experiment, ExperimentResult, NullProgress, Progress, RunOptions

__all__ = ["Experiment", "ExperimentResult", "NullProgress", "Progress", "RunOptions"]
