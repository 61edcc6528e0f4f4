"""Pure numerics of the ball bouncing map: numpy/scipy only, no files, no printing."""

from .flight import (
    INTEGRATORS,
    FlightSettings,
    Impact,
    Segment,
    Trajectory,
    impact_velocity,
    leave_phase,
    simulate,
)
from .impact import can_fly, gap, gap_slope, launch_slope, next_impact_phase
from .linear import (
    Stability,
    complex_boundaries_g,
    eigenvalues,
    finite_difference_jacobian,
    flip_boundary_g,
    is_complex_regime,
    jacobian,
    racket_acceleration_at_impact_g,
    spectral_radius,
    stability,
)
from .maps import MapStep, Orbit, iterate_map, iterate_orbit, map_step, velocity_after_impact
from .params import (
    FixedPoint,
    ModelError,
    ModelParams,
    NoFixedPointError,
    phase_difference,
    wrap_phase,
)

__all__ = [
    "INTEGRATORS", "FlightSettings", "Impact", "Segment", "Trajectory", "impact_velocity",
    "leave_phase", "simulate",
    "FixedPoint", "MapStep", "Orbit", "iterate_orbit", "ModelError", "ModelParams", "NoFixedPointError", "Stability",
    "can_fly", "complex_boundaries_g", "eigenvalues", "finite_difference_jacobian",
    "flip_boundary_g", "gap", "gap_slope", "is_complex_regime", "iterate_map", "jacobian",
    "launch_slope", "map_step", "next_impact_phase", "phase_difference",
    "racket_acceleration_at_impact_g", "spectral_radius", "stability", "velocity_after_impact",
    "wrap_phase",
]
