"""The errors bounce raises on purpose: one base class, :class:`BounceError`, and subclasses
that tell a caller what went wrong and what to change.

From Python, ``except bounce_cli.BounceError`` catches every one of them; the command line
prints any of them as one line ``bounce: error: <message>`` and exits 2. The message is for
people; a program tells the errors apart by their classes (never by a message's text)::

    BounceError                      everything below
    +-- ConfigError                  a config or an override (key, value, range, YAML)
    +-- DataError                    data that cannot be analysed as asked
    |   +-- NoPerturbedImpactError     impacts without a perturbed one (section 7's windows)
    |   +-- TooFewObservationsError    fewer trials or points than an estimate needs (a
    |                                  design that cannot answer: a study skips the analysis)
    +-- ModelError                   parameters the map cannot be evaluated with
    |   +-- NoFixedPointError          eq. 8 has no solution (|cos theta~| > 1)
    |   +-- NotStableError             the fixed point is not linearly stable (eq. 10),
    |                                  so eq. 19 has no stationary covariance
    +-- OutputDirError               the output directory cannot be used
    |   +-- RunDirectoryBusy           another bounce run is writing there (its lock)
    +-- ClusterError                 the Dask cluster cannot be used
    +-- MissingResults               a results file a claim needs is absent

Each also derives from the built-in exception it was before (``ValueError`` for the first
four families, ``RuntimeError`` for :class:`ClusterError`), so that older ``except
ValueError`` clauses keep working; :class:`NoPerturbedImpactError` is a :class:`ModelError`
too, as the data statistics raised before it had a class.

Not here, on purpose: ``interrupts.Interrupted`` (SIGINT, SIGTERM, SIGHUP) derives from
``BaseException`` so that ``except Exception`` lets it through; ``parallel.WorkerError`` (a
task failed in a worker, or a worker died) carries the worker's traceback and propagates as
a bug report, not as a one-line user error.

Standard library only: every module may import this one, and it imports none of them.
"""

from __future__ import annotations

__all__ = [
    "BounceError",
    "ClusterError",
    "ConfigError",
    "DataError",
    "MissingResults",
    "ModelError",
    "NoFixedPointError",
    "NoPerturbedImpactError",
    "NotStableError",
    "OutputDirError",
    "RunDirectoryBusy",
    "TooFewObservationsError",
]


class BounceError(Exception):
    """The base of every error bounce raises on purpose; its message is one line naming
    what to change (the command line prints it as ``bounce: error: <message>``, exit 2)."""


class ConfigError(BounceError, ValueError):
    """A user error in a config or an override: one line naming the key and the reason."""


class DataError(BounceError, ValueError):
    """Data that cannot be analysed as asked (a recording's impacts do not hold what the
    analysis needs)."""


class ModelError(BounceError, ValueError):
    """Parameters that the ball bouncing map cannot be evaluated with."""


class NoFixedPointError(ModelError):
    """The parameters admit no period-1 fixed point (|cos theta~| > 1 in eq. 8)."""


class NotStableError(ModelError):
    """The period-1 fixed point is not linearly stable (spectral radius of eq. 9's J not
    below 1, eq. 10): the stationary statistics of eq. 19 do not exist."""


class TooFewObservationsError(DataError, ConfigError, ModelError):
    """Fewer trials or points than an estimate needs (a trend over trials from 2 trials, a
    line through 2 points): the data may be fine, the design cannot answer the question.
    ``bounce study`` then skips that analysis of the unit with this reason (a warning, not a
    failure). A ConfigError and a ModelError too, as the checks raised before it had a class."""


class NoPerturbedImpactError(DataError, ModelError):
    """Impacts without a perturbed one: section 7's response windows cannot be aligned.

    A :class:`ModelError` as well, as these data statistics raised before this class."""


class OutputDirError(BounceError, ValueError):
    """The output directory cannot be used (holds another config's results, not writable)."""


class RunDirectoryBusy(OutputDirError):
    """Another bounce run holds the output directory's lock (it is writing there)."""


class ClusterError(BounceError, RuntimeError):
    """The Dask cluster cannot be used: ``distributed`` missing, scheduler unreachable."""


class MissingResults(BounceError):
    """A results file a claim needs is absent (run ``bounce reproduce`` first)."""
