"""A basin atlas over parameters: at each parameter point the period-1 fixed point (eqs. 7, 8)
and its spectral radius (eq. 10), and a basin on a (theta0, v0) grid classified as in
section 3 (Fig. 4), summarised by its outcome fractions, its basin entropy and boundary basin
entropy and, on request, its uncertainty exponent (``analysis.basin_measures``).

A parameter point is the model with some of alpha, g, racket_amplitude and racket_period
replaced, or with ``ac_g`` set: the racket acceleration at impact AC (units of g, <= 0) put
in place through the explicit amplitude of section 4 (``linear.racket_amplitude_for_ac``, at
the point's alpha, g and racket period), so that an alpha x AC grid is Fig. 5's plane.

Each parameter point is one independent task (:func:`evaluate_point`), with its own random
stream (the uncertainty exponent draws random initial conditions) from a child of
``SeedSequence(seed).spawn``: results do not depend on which worker, process or machine ran
it. Where the period-1 orbit does not exist (eq. 8: cos theta~ > 1), no initial condition can
be ``period1``; the same iteration still decides ``sticking``, ``below_racket`` and
``undecided`` (:func:`classify_points`), and the fixed-point columns are NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .basin_measures import basin_entropy, uncertainty_exponent
from .classify import OUTCOMES, Classification, ClassifySettings, classify_batch, outcome_names
from ..model.linear import racket_acceleration_at_impact_g, stability, with_parameters
from ..model.params import ModelError, ModelParams

#: parameters a sweep axis can set: CSV column (unit in the name) and axis label
SWEEP_PARAMETERS: dict[str, tuple[str, str]] = {
    "alpha": ("alpha", r"coefficient of restitution $\alpha$"),
    "g": ("g_m_s2", r"gravitational acceleration $g$ (m/s$^2$)"),
    "racket_amplitude": ("racket_amplitude_m", r"racket amplitude $a_r$ (m)"),
    "racket_period": ("racket_period_s", r"racket period $\tau$ (s)"),
    "ac_g": ("ac_g", r"racket acceleration at impact AC (g)"),
}


def parameter_point(base: ModelParams, values: dict[str, float]) -> ModelParams:
    """``base`` with the given parameters replaced (``model.linear.with_parameters``);
    ``ac_g`` (<= 0) sets the racket amplitude that puts the fixed point at that AC (section
    4's explicit form) at the point's other parameters. Raises ModelError for a parameter a
    sweep does not offer or an invalid point."""
    unknown = set(values) - set(SWEEP_PARAMETERS)
    if unknown:
        raise ModelError(f"cannot sweep {sorted(unknown)}: choose from "
                         f"{', '.join(SWEEP_PARAMETERS)}")
    return with_parameters(base, values)


def classify_points(theta0, v0, params: ModelParams,
                    settings: ClassifySettings = ClassifySettings()) -> Classification:
    """Section 3's classification (``classify_batch``) at any parameters: where the period-1
    fixed point does not exist (eq. 8), no point is ``period1`` and every other outcome is
    decided by the same iteration (sticking, below the racket, undecided after
    ``max_iterations`` impacts)."""
    return classify_batch(theta0, v0, params, settings, require_fixed_point=False)


@dataclass(frozen=True)
class Axis:
    """numpy.linspace(start, stop, num)."""

    start: float
    stop: float
    num: int

    def values(self) -> np.ndarray:
        return np.linspace(self.start, self.stop, self.num)


@dataclass(frozen=True)
class UncertaintySettings:
    """The uncertainty exponent: ``samples`` random initial conditions per eps, eps given
    as fractions of the basin grid's spans."""

    eps: tuple[float, ...]
    samples: int


@dataclass(frozen=True)
class PointTask:
    """One parameter point of a sweep: everything a worker needs, nothing else."""

    index: int
    params: ModelParams
    theta0_deg: Axis
    v0_m_s: Axis
    settings: ClassifySettings
    entropy_box: int
    uncertainty: UncertaintySettings | None
    seed: np.random.SeedSequence


def point_tasks(points: list[ModelParams], theta0_deg: Axis, v0_m_s: Axis,
                settings: ClassifySettings, entropy_box: int,
                uncertainty: UncertaintySettings | None, seed: int) -> list[PointTask]:
    """One task per parameter point, point i with child i of ``SeedSequence(seed)``."""
    seeds = np.random.SeedSequence(seed).spawn(len(points))
    return [PointTask(i, p, theta0_deg, v0_m_s, settings, entropy_box, uncertainty, s)
            for i, (p, s) in enumerate(zip(points, seeds))]


#: a basin point decided at this impact or later, other than by reaching the period-1 orbit,
#: may have been decided by a chaotic transient whose last bits another machine rounds
#: otherwise (measured in bounce bifurcation: with g moved by ulps, sticking impacts changed
#: from impact 36 on, never before)
LATE_ITERATIONS = 30


def evaluate_point(task: PointTask) -> dict[str, Any]:
    """The sweep's numbers at one parameter point, as plain Python numbers (JSON-able, so a
    finished point can be stored and read back exactly):

    ``row``: ``ac_g``, ``fixed_point_v_m_s``, ``fixed_point_theta_deg``, ``spectral_radius``
    (eqs. 7, 8, 10; NaN without a fixed point), ``fraction_<outcome>`` for each outcome of
    section 3, ``points_decided_late`` (not reaching period 1, decided after
    ``LATE_ITERATIONS`` impacts or more, or undecided), ``basin_entropy``,
    ``boundary_basin_entropy`` (nats), ``boundary_boxes``, ``basin_points`` and, with
    ``task.uncertainty``, ``uncertainty_exponent`` and ``uncertainty_exponent_se``;
    ``uncertainty``: the eps and uncertain fractions (or None).
    """
    params = task.params
    row: dict[str, Any] = {}
    if params.cos_theta_fixed() <= 1.0:
        fp = params.fixed_point()
        row.update(ac_g=float(racket_acceleration_at_impact_g(params)),
                   fixed_point_v_m_s=fp.v_m_s, fixed_point_theta_deg=fp.theta_deg,
                   spectral_radius=float(stability(params).spectral_radius))
    else:
        row.update(ac_g=math.nan, fixed_point_v_m_s=math.nan, fixed_point_theta_deg=math.nan,
                   spectral_radius=math.nan)
    theta_grid, v_grid = np.meshgrid(np.deg2rad(task.theta0_deg.values()), task.v0_m_s.values())
    classified = classify_points(theta_grid, v_grid, params, task.settings)
    outcome = classified.outcome
    names = outcome_names(task.settings)  # exact sticking (min_hop_s 0): locked, resting too
    counts = np.bincount(outcome.ravel(), minlength=len(names))
    for name, count in zip(names, counts):
        row[f"fraction_{name}"] = float(count / outcome.size)
    if names is not OUTCOMES:  # the locked orbit's period in racket cycles (0: none)
        row["locked_cycles"] = int(classified.locked_cycles)
    # the points a last bit can decide: those that did not reach the period-1 orbit and were
    # decided (or left undecided) only after LATE_ITERATIONS impacts or more
    late = (outcome != OUTCOMES.index("period1")) & (classified.iterations >= LATE_ITERATIONS)
    row["points_decided_late"] = int(late.sum())
    entropy = basin_entropy(outcome, box=task.entropy_box)
    row.update(basin_entropy=entropy.basin_entropy,
               boundary_basin_entropy=entropy.boundary_basin_entropy,
               boundary_boxes=entropy.boundary_boxes, basin_points=int(outcome.size))
    curve = None
    if task.uncertainty is not None:
        def outcome_of(theta0, v0):
            return classify_points(theta0, v0, params, task.settings).outcome

        theta_span = tuple(np.deg2rad([task.theta0_deg.start, task.theta0_deg.stop]))
        fit = uncertainty_exponent(
            outcome_of, theta_span, (task.v0_m_s.start, task.v0_m_s.stop),
            np.asarray(task.uncertainty.eps), task.uncertainty.samples,
            np.random.default_rng(task.seed))
        row.update(uncertainty_exponent=fit.alpha, uncertainty_exponent_se=fit.alpha_se)
        curve = {"eps": [float(e) for e in fit.eps],
                 "uncertain_fraction": [float(f) for f in fit.uncertain_fraction]}
    return {"index": task.index, "row": row, "uncertainty": curve}

