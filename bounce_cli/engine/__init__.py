"""Pure numerics of the ball bouncing map: numpy/scipy only, no files, no printing."""

from .classify import (
    BELOW_RACKET,
    OUTCOMES,
    PERIOD1,
    STICKING,
    UNDECIDED,
    Classification,
    ClassifySettings,
    classify_batch,
    classify_grid,
)
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
from .impulse import (
    ImpulseResponse,
    impulse_response_full,
    impulse_response_linear,
    perturbed_velocity,
    relaxation_impacts,
)
from .linear import (
    ContractionFit,
    MinimumRadius,
    Stability,
    ac_explicit_g,
    characteristic_c,
    empirical_contraction_rate,
    iterate_linear,
    min_stable_spectral_radius,
    racket_amplitude_for_ac,
    stable_ac_range_g,
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
from .regression import (
    LineFit,
    TrialMeans,
    eq15_amplitude,
    eq15_slope,
    ols_line,
    period_for_height,
    phase_from_slope,
    simulate_trial,
)
from .stochastic import (
    PAIR_NAMES,
    PAIRS,
    VELOCITY_PHASES,
    StochasticRuns,
    Var1Theory,
    correlations_from_covariances,
    lagged_covariances,
    map_noise_covariance,
    paper_noise_covariance,
    sample_correlations,
    simulate_stochastic_map,
    stationary_covariance,
    stochastic_step,
    var1_theory,
)
from .params import (
    FixedPoint,
    ModelError,
    ModelParams,
    NoFixedPointError,
    phase_difference,
    wrap_phase,
)

__all__ = [
    "BELOW_RACKET", "OUTCOMES", "PERIOD1", "STICKING", "UNDECIDED", "Classification",
    "ClassifySettings", "classify_batch", "classify_grid",
    "INTEGRATORS", "FlightSettings", "Impact", "Segment", "Trajectory", "impact_velocity",
    "leave_phase", "simulate",
    "FixedPoint", "MapStep", "Orbit", "iterate_orbit", "ModelError", "ModelParams", "NoFixedPointError", "Stability",
    "can_fly", "complex_boundaries_g", "eigenvalues", "finite_difference_jacobian",
    "flip_boundary_g", "gap", "gap_slope", "is_complex_regime", "iterate_map", "jacobian",
    "launch_slope", "map_step", "next_impact_phase", "phase_difference",
    "racket_acceleration_at_impact_g", "spectral_radius", "stability", "velocity_after_impact",
    "wrap_phase", "ContractionFit", "MinimumRadius", "ac_explicit_g", "characteristic_c",
    "empirical_contraction_rate", "iterate_linear", "min_stable_spectral_radius",
    "racket_amplitude_for_ac", "stable_ac_range_g", "ImpulseResponse", "impulse_response_full",
    "impulse_response_linear", "perturbed_velocity", "relaxation_impacts",
    "wrap_phase",
    # stochastic map and VAR(1) theory (section 6)
    "PAIR_NAMES", "PAIRS", "VELOCITY_PHASES", "StochasticRuns", "Var1Theory",
    "correlations_from_covariances", "lagged_covariances", "map_noise_covariance",
    "paper_noise_covariance", "sample_correlations", "simulate_stochastic_map",
    "stationary_covariance", "stochastic_step", "var1_theory",
    # amplitude-period relation (section 5, eq. 15)
    "LineFit", "TrialMeans", "eq15_amplitude", "eq15_slope", "ols_line", "period_for_height",
    "phase_from_slope", "simulate_trial",
]
