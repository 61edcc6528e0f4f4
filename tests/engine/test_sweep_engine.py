"""engine.sweep: parameter points (AC through section 4's explicit amplitude), section 3's
classification where no period-1 orbit exists (against single orbits of the map), and one
parameter point's numbers against the basin experiment's committed Fig. 4 fractions."""

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bounce_cli.analysis.basin_measures import basin_entropy
from bounce_cli.analysis.classify import OUTCOMES, ClassifySettings, classify_batch
from bounce_cli.model.linear import flip_boundary_g, racket_acceleration_at_impact_g, stability
from bounce_cli.model.maps import iterate_orbit
from bounce_cli.model.params import ModelError, NoFixedPointError
from bounce_cli.analysis.sweep import (
    Axis,
    UncertaintySettings,
    classify_points,
    evaluate_point,
    parameter_point,
    point_tasks,
)

RESULTS = Path(__file__).resolve().parents[2] / "results"


@pytest.mark.parametrize("alpha", [0.2, 0.5, 0.8])
@pytest.mark.parametrize("ac", [-1.8, -1.0, -0.3, -0.05])
def test_ac_sets_the_amplitude_that_puts_the_fixed_point_there(paper_params, alpha, ac):
    point = parameter_point(paper_params, {"alpha": alpha, "ac_g": ac, "racket_period": 0.7})
    assert (point.alpha, point.g, point.racket_period) == (alpha, paper_params.g, 0.7)
    # AC measured at the fixed point of eq. 8 (not the explicit formula it was set by)
    assert racket_acceleration_at_impact_g(point) == pytest.approx(ac, rel=1e-9, abs=1e-12)


def test_the_flip_boundary_of_eq14_is_where_the_radius_reaches_one(paper_params):
    for alpha in (0.3, 0.5, 0.8):
        flip = float(flip_boundary_g(alpha))
        inside = parameter_point(paper_params, {"alpha": alpha, "ac_g": flip * (1 - 1e-6)})
        outside = parameter_point(paper_params, {"alpha": alpha, "ac_g": flip * (1 + 1e-6)})
        assert stability(inside).spectral_radius < 1 < stability(outside).spectral_radius


def test_bad_points_are_model_errors(paper_params):
    with pytest.raises(ModelError, match="ac_g must be <= 0"):
        parameter_point(paper_params, {"ac_g": 0.2})
    with pytest.raises(ModelError, match="cannot both be swept"):
        parameter_point(paper_params, {"ac_g": -1.0, "racket_amplitude": 0.3})
    with pytest.raises(ModelError, match="alpha"):
        parameter_point(paper_params, {"alpha": 1.0, "ac_g": -1.0})
    with pytest.raises(ModelError, match="cannot sweep"):
        parameter_point(paper_params, {"gamma": 2.0})


def test_without_a_fixed_point_the_classifier_still_decides_every_other_outcome(paper_params):
    """Below eq. 8's existence threshold classify_batch refuses (it needs the fixed point);
    classify_points decides sticking / below the racket / undecided, and each point agrees
    with a single orbit of the map (engine.maps.iterate_orbit) and its stop reason."""
    low = parameter_point(paper_params, {"racket_amplitude": 0.15})
    assert low.cos_theta_fixed() > 1
    with pytest.raises(NoFixedPointError):
        classify_batch(0.5, 5.0, low)
    settings = ClassifySettings(max_iterations=60)
    rng = np.random.default_rng(3)
    theta0 = np.r_[rng.uniform(0, 2 * math.pi, 150), 0.0, 0.3]
    v0 = np.r_[rng.uniform(0, 10, 150), 0.0, 0.5]  # the last two below the rising racket
    result = classify_points(theta0, v0, low, settings)
    names = result.names()
    assert "period1" not in names
    for th, v, name, k in zip(theta0, v0, names, result.iterations):
        orbit = iterate_orbit(th, v, low, settings.max_iterations, settings.min_hop_s)
        expected = orbit.stop_reason or "undecided"
        assert name == expected
        assert k == (len(orbit.theta) - 1 if name != "below_racket" else 0)
    assert {"sticking", "below_racket"} <= set(names)


def test_with_a_fixed_point_it_is_the_basins_classifier(paper_params):
    rng = np.random.default_rng(4)
    theta0, v0 = rng.uniform(0, 2 * math.pi, 400), rng.uniform(0, 10, 400)
    ours, basin = classify_points(theta0, v0, paper_params), classify_batch(theta0, v0,
                                                                            paper_params)
    assert np.array_equal(ours.outcome, basin.outcome)
    assert np.array_equal(ours.iterations, basin.iterations)


def tasks_at(points, num=40, uncertainty=None, seed=1):
    return point_tasks(points, Axis(0.0, 360.0, num), Axis(0.0, 10.0, num), ClassifySettings(),
                       5, uncertainty, seed)


def test_one_point_at_the_papers_parameters_is_fig4(paper_params):
    """The paper's 400 x 400 grid: the fractions of the committed bounce basin run
    (results/basin/fractions.csv), the fixed point of eqs. 7, 8 and radius 0.5 (eq. 10)."""
    result = evaluate_point(tasks_at([paper_params], num=400)[0])
    row = result["row"]
    fractions = pd.read_csv(RESULTS / "basin" / "fractions.csv").set_index("outcome")
    for outcome in OUTCOMES:
        assert row[f"fraction_{outcome}"] == pytest.approx(fractions.fraction[outcome],
                                                           abs=1e-12)
    fp = paper_params.fixed_point()
    assert row["fixed_point_v_m_s"] == fp.v_m_s
    assert row["fixed_point_v_m_s"] == pytest.approx(math.pi * 9.81 / (2 * math.pi / 0.92))
    assert row["spectral_radius"] == pytest.approx(0.5, abs=1e-3)
    assert row["basin_points"] == 160_000 and result["uncertainty"] is None


def test_entropies_are_those_of_the_classified_grid(paper_params):
    task = tasks_at([paper_params], num=30)[0]
    row = evaluate_point(task)["row"]
    theta, v = np.meshgrid(np.deg2rad(task.theta0_deg.values()), task.v0_m_s.values())
    grid = classify_batch(theta, v, paper_params).outcome
    direct = basin_entropy(grid, box=5)
    assert row["basin_entropy"] == direct.basin_entropy
    assert row["boundary_basin_entropy"] == direct.boundary_basin_entropy
    assert row["boundary_boxes"] == direct.boundary_boxes
    assert sum(row[f"fraction_{o}"] for o in OUTCOMES) == pytest.approx(1.0, abs=1e-12)


def test_points_decided_late_are_the_grids_late_non_period1_points(paper_params):
    """At an unstable point (AC -1.6 g): every undecided point is late, and the late ones are
    the grid's points not on period 1 whose classification took 30 impacts or more."""
    from bounce_cli.analysis.sweep import LATE_ITERATIONS, parameter_point

    unstable = parameter_point(paper_params, {"ac_g": -1.6})
    task = tasks_at([unstable], num=30)[0]
    row = evaluate_point(task)["row"]
    theta, v = np.meshgrid(np.deg2rad(task.theta0_deg.values()), task.v0_m_s.values())
    grid = classify_batch(theta, v, unstable)
    late = (grid.outcome != OUTCOMES.index("period1")) & (grid.iterations >= LATE_ITERATIONS)
    assert row["points_decided_late"] == int(late.sum())
    assert row["points_decided_late"] >= round(row["fraction_undecided"] * 900) > 0


def test_no_fixed_point_gives_nan_fixed_point_columns_and_no_period1(paper_params):
    low = parameter_point(paper_params, {"racket_amplitude": 0.15})
    row = evaluate_point(tasks_at([low], num=20)[0])["row"]
    for key in ("ac_g", "fixed_point_v_m_s", "fixed_point_theta_deg", "spectral_radius"):
        assert math.isnan(row[key])
    assert row["fraction_period1"] == 0.0
    assert row["fraction_sticking"] + row["fraction_below_racket"] + row[
        "fraction_undecided"] == pytest.approx(1.0)


def test_each_point_has_its_own_random_stream_whatever_runs_it(paper_params):
    uncertainty = UncertaintySettings((3e-3, 1e-2, 3e-2), 200)
    other = parameter_point(paper_params, {"alpha": 0.6})
    a = tasks_at([paper_params, other], num=10, uncertainty=uncertainty, seed=5)
    b = tasks_at([paper_params, other], num=10, uncertainty=uncertainty, seed=5)
    first, again = evaluate_point(a[1]), evaluate_point(b[1])
    assert first == again  # the same point, the same numbers
    # point 1's stream is child 1 of SeedSequence(5), not the stream of point 0
    assert a[1].seed.spawn_key != a[0].seed.spawn_key
    assert np.random.default_rng(a[1].seed).random() != np.random.default_rng(a[0].seed).random()
    curve = first["uncertainty"]
    assert curve["eps"] == [3e-3, 1e-2, 3e-2]
    # more perturbation, more uncertain points (a boundary of positive length)
    assert curve["uncertain_fraction"][0] <= curve["uncertain_fraction"][-1]
    assert 0 < curve["uncertain_fraction"][-1] < 1
    assert math.isfinite(first["row"]["uncertainty_exponent"])


def test_exact_sticking_point_counts_locked_orbits_with_their_period(paper_params):
    """classify.min_hop_s 0 at the paper's point: the 1 ms rule's sticking fraction is the
    locked fraction (period 1 racket cycle), the other fractions are unchanged."""
    def task(settings):
        return point_tasks([paper_params], Axis(0.0, 360.0, 30), Axis(0.0, 10.0, 30),
                           settings, 5, None, 1)[0]

    exact = evaluate_point(task(ClassifySettings(min_hop_s=0.0)))["row"]
    cut = evaluate_point(task(ClassifySettings()))["row"]
    assert exact["fraction_sticking"] == 0.0 and "fraction_locked" not in cut
    assert exact["fraction_locked"] == cut["fraction_sticking"] > 0.3
    assert exact["locked_cycles"] == 1 and exact["fraction_resting"] == 0.0
    for name in ("period1", "below_racket", "undecided"):
        assert exact[f"fraction_{name}"] == cut[f"fraction_{name}"]
