"""The map itself: parameters and the fixed point (eqs. 4, 7, 8), the first-impact solver
(eq. 6), the map's step and orbits (eqs. 5, 6), the continuous flight with sticking
(eqs. 1-4), linear stability (eqs. 9-14), the compiled kernel and its scalar reference, and
the map with racket period control. Numpy/scipy only: no files, no printing::

    from bounce_cli.model import ModelParams, stability
    p = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
    p.fixed_point(), stability(p).spectral_radius
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

if TYPE_CHECKING:  # for type checkers: the names as if imported eagerly
    from .flight import FlightSettings, Trajectory, simulate
    from .impact import next_impact_phase
    from .linear import Stability, flip_boundary_g, jacobian, stability
    from .maps import Orbit, iterate_map, iterate_orbit, map_step
    from .params import FixedPoint, ModelError, ModelParams, NoFixedPointError, wrap_phase

#: exported name -> its submodule, imported on first use (PEP 562)
_EXPORTS = {
    **dict.fromkeys(("FixedPoint", "ModelError", "ModelParams", "NoFixedPointError",
                     "wrap_phase"), "params"),
    "next_impact_phase": "impact",
    **dict.fromkeys(("Orbit", "iterate_map", "iterate_orbit", "map_step"), "maps"),
    **dict.fromkeys(("Stability", "flip_boundary_g", "jacobian", "stability"), "linear"),
    **dict.fromkeys(("FlightSettings", "Trajectory", "simulate"), "flight"),
}

__all__ = [
    # parameters, fixed point (eqs. 4, 7, 8)
    "ModelParams", "FixedPoint", "ModelError", "NoFixedPointError", "wrap_phase",
    # the map (eqs. 5, 6)
    "next_impact_phase", "map_step", "iterate_map", "iterate_orbit", "Orbit",
    # linear stability (eqs. 9-14)
    "jacobian", "stability", "Stability", "flip_boundary_g",
    # continuous motion (eqs. 1-4, Fig. 3)
    "simulate", "FlightSettings", "Trajectory",
]

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
