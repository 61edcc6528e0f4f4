"""bounce: the experiments of the ball bouncing map paper, from the command line or Python.

In a notebook (see :mod:`bounce_cli.api`)::

    import bounce_cli
    result = bounce_cli.run("basin", set={"grid.theta0_deg.num": 40, "grid.v0_m_s.num": 30})
    result.frames["basin.csv"], result.figures["basin.png"]

The names below are imported on first use (PEP 562), so that ``bounce --help`` and a
worker process import none of numpy, pandas or the experiments until they need them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .lazy import lazy_exports
from .version import __version__

if TYPE_CHECKING:  # for type checkers: the names as if imported eagerly
    from .api import (
        ExperimentResult,
        FixedPoint,
        ModelParams,
        Orbit,
        Stability,
        extract,
        iterate_orbit,
        map_step,
        read_recording,
        run,
        stability,
    )
    from .errors import (
        BounceError,
        ClusterError,
        ConfigError,
        DataError,
        ModelError,
        NoFixedPointError,
        OutputDirError,
    )

#: exported name -> the module it comes from, imported on first use
_EXPORTS = {
    "run": "api",
    "read_recording": "api",
    "extract": "api",
    "ExperimentResult": "api",
    "ModelParams": "api",
    "FixedPoint": "api",
    "map_step": "api",
    "iterate_orbit": "api",
    "Orbit": "api",
    "stability": "api",
    "Stability": "api",
    "BounceError": "errors",
    "ConfigError": "errors",
    "DataError": "errors",
    "ModelError": "errors",
    "NoFixedPointError": "errors",
    "OutputDirError": "errors",
    "ClusterError": "errors",
}

__all__ = [
    "__version__",
    # the notebook API (bounce_cli.api)
    "run", "read_recording", "extract", "ExperimentResult",
    # what a caller catches (bounce_cli.errors; every one a BounceError)
    "BounceError", "ConfigError", "DataError", "ModelError", "NoFixedPointError",
    "OutputDirError", "ClusterError",
    # the model (eqs. 5-10)
    "ModelParams", "FixedPoint", "map_step", "iterate_orbit", "Orbit", "stability", "Stability",
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
