"""Pure numerics of the ball bouncing map: numpy/scipy only, no files, no printing.

The entry points a library user needs; everything else lives in the submodules
(``params``, ``impact``, ``maps``, ``linear``, ``classify``, ``flight``, ``stochastic``,
``impulse``, ``regression``, ``reference``, ``roots``)::

    from bounce_cli.engine import ModelParams, classify_grid, stability
    p = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
    p.fixed_point(), stability(p).spectral_radius
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .. import lazy_exports

if TYPE_CHECKING:  # for type checkers: the names as if imported eagerly
    from .classify import OUTCOMES, Classification, ClassifySettings, classify_batch, classify_grid
    from .flight import FlightSettings, Trajectory, simulate
    from .impact import next_impact_phase
    from .impulse import find_threshold, impulse_response_full, impulse_response_linear
    from .linear import Stability, flip_boundary_g, jacobian, stability
    from .maps import Orbit, iterate_map, iterate_orbit, map_step
    from .params import FixedPoint, ModelError, ModelParams, NoFixedPointError, wrap_phase
    from .regression import eq15_slope, ols_line
    from .stochastic import simulate_stochastic_map, var1_theory

#: exported name -> its submodule, imported on first use (PEP 562), so that importing one
#: submodule (the CLI's start, a worker process) does not import them all (scipy among them)
_EXPORTS = {
    "OUTCOMES": "classify",
    "Classification": "classify",
    "ClassifySettings": "classify",
    "classify_batch": "classify",
    "classify_grid": "classify",
    "FlightSettings": "flight",
    "Trajectory": "flight",
    "simulate": "flight",
    "next_impact_phase": "impact",
    "find_threshold": "impulse",
    "impulse_response_full": "impulse",
    "impulse_response_linear": "impulse",
    "Stability": "linear",
    "flip_boundary_g": "linear",
    "jacobian": "linear",
    "stability": "linear",
    "Orbit": "maps",
    "iterate_map": "maps",
    "iterate_orbit": "maps",
    "map_step": "maps",
    "FixedPoint": "params",
    "ModelError": "params",
    "ModelParams": "params",
    "NoFixedPointError": "params",
    "wrap_phase": "params",
    "eq15_slope": "regression",
    "ols_line": "regression",
    "simulate_stochastic_map": "stochastic",
    "var1_theory": "stochastic",
}

__all__ = [
    # parameters, fixed point (eqs. 4, 7, 8)
    "ModelParams", "FixedPoint", "ModelError", "NoFixedPointError", "wrap_phase",
    # the map (eqs. 5, 6)
    "next_impact_phase", "map_step", "iterate_map", "iterate_orbit", "Orbit",
    # linear stability (eqs. 9-14)
    "jacobian", "stability", "Stability", "flip_boundary_g",
    # basin classification (section 3, Fig. 4)
    "classify_batch", "classify_grid", "ClassifySettings", "Classification", "OUTCOMES",
    # continuous motion (eqs. 1-4, Fig. 3)
    "simulate", "FlightSettings", "Trajectory",
    # stochastic map and eq. 19 (section 6)
    "simulate_stochastic_map", "var1_theory",
    # impulse responses (section 7)
    "impulse_response_full", "impulse_response_linear", "find_threshold",
    # eq. 15 (section 5)
    "eq15_slope", "ols_line",
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
