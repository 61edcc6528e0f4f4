"""The reproduction rules of the tables filled by chaotic orbits (``paper/chaotic_tables``):
another machine's last bits are stood in for by moving g by a few ulps (it reaches every
orbit from the first impact, as another libm's sin and cos do), which must be accepted,
while a real change of the model (alpha or g by 1e-6) must not be; and each rule on tables
built by hand, so that each can fail on its own."""

import io
import math

import numpy as np
import pandas as pd
import pytest

import bounce_cli
from bounce_cli.paper.chaotic_tables import (
    LATE_IMPACT,
    allowed_flips,
    cycles_agree,
    late_outcome,
    orbit_points_drift,
    samples_agree,
    widest_gap_cut,
)
from bounce_cli.paper.reproduce import table_drift, value_drift
from bounce_cli.runtime.artifacts import RunTables

EPS = np.finfo(float).eps
#: a small sweep across the chaotic band and its crisis at alpha 0.5 (Gamma 1.70-1.80): chaotic
#: orbits, and chaotic transients that end in sticking after 30-400 impacts
SMALL_BIFURCATION = {
    "sweep.start": 1.70, "sweep.stop": 1.80, "sweep.num": 11,
    "initial_conditions.theta0_deg": [45, 90, 135], "initial_conditions.v0_m_s": [3, 5, 7],
    "iterate.transient_impacts": 300, "iterate.measured_impacts": 400, "flip.locate": False}


def round_trip(frames):
    """The tables as read back from their CSVs (what reproduce compares)."""
    return {n: pd.read_csv(io.StringIO(f.to_csv(index=False))) for n, f in frames.items()}


def run_frames(name, **settings):
    return round_trip(bounce_cli.run(name, set=settings).frames)


def drift_by_table(name, fresh, committed, config=None):
    tables = RunTables(fresh, committed, config or {})
    return {t: table_drift(name, t, fresh[t], committed[t], tables) for t in committed}


@pytest.fixture(scope="module")
def small_bifurcation():
    return run_frames("bifurcation", **SMALL_BIFURCATION)


@pytest.mark.parametrize("ulps", [-2, 1, 3])
def test_a_bifurcation_moved_by_ulps_is_reproduced_value_by_value_it_is_not(
        small_bifurcation, ulps):
    moved = run_frames("bifurcation", **SMALL_BIFURCATION, **{"model.g": 9.81 * (1 + ulps * EPS)})
    # the last bits reach the chaotic orbits: compared value by value, they drift
    plain = {t: value_drift("bifurcation", t, moved[t], small_bifurcation[t])
             for t in ("attractors.csv", "bifurcation.csv")}
    assert all(plain.values()), plain
    late = late_outcome(small_bifurcation["attractors.csv"])
    changed = (moved["attractors.csv"].stuck_at_impact
               != small_bifurcation["attractors.csv"].stuck_at_impact).to_numpy()
    assert changed.any() and late[changed].all()  # only late outcomes moved
    assert drift_by_table("bifurcation", moved, small_bifurcation) == {
        t: [] for t in small_bifurcation}


@pytest.mark.parametrize("change", [{"model.alpha": 0.5 * (1 + 1e-6)},
                                    {"model.g": 9.81 * (1 + 1e-6)}])
def test_a_real_change_of_the_model_is_a_drift(small_bifurcation, change):
    moved = run_frames("bifurcation", **SMALL_BIFURCATION, **change)
    drift = drift_by_table("bifurcation", moved, small_bifurcation)
    assert drift["attractors.csv"] and drift["bifurcation.csv"], drift


def test_a_continuation_diagram_moved_by_ulps_is_reproduced():
    small = {"starts": [{"at": 1.7, "cycles": 1}], "steps.max_period": 4, "range.low": 1.65,
             "range.high": 1.8, "diagram.num": 12, "diagram.transient_impacts": 300}
    committed = run_frames("continuation", **small)
    moved = run_frames("continuation", **small, **{"model.g": 9.81 * (1 + 2 * EPS)})
    assert value_drift("continuation", "diagram.csv", moved["diagram.csv"],
                       committed["diagram.csv"])
    assert drift_by_table("continuation", moved, committed)["diagram.csv"] == []
    alpha = run_frames("continuation", **small, **{"model.alpha": 0.5 * (1 + 1e-5)})
    assert drift_by_table("continuation", alpha, committed)["diagram.csv"]


def test_a_periodic_orbit_is_the_same_cycle_from_any_of_its_impacts():
    cycle = pd.DataFrame({"v_m_s": [4.0, 5.0, 6.0] * 4,
                          "theta_deg": [359.9999999, 120.0, 240.0] * 4})
    later = cycle.iloc[2:].reset_index(drop=True)  # the recording starts two impacts later
    assert cycles_agree(later, cycle, 3, 1e-6, 1e-9)
    wrapped = cycle.assign(theta_deg=np.mod(cycle.theta_deg + 2e-7, 360.0))  # across 360
    assert cycles_agree(wrapped, cycle, 3, 1e-6, 1e-9)
    off = later.assign(v_m_s=later.v_m_s.where(later.v_m_s != 5.0, 5.00001))
    assert not cycles_agree(off, cycle, 3, 1e-6, 1e-9)


def test_two_samples_of_one_attractor_agree_and_another_band_does_not():
    rng = np.random.default_rng(5)

    def band(centre, n=64):  # a chaotic band of phases across 0/360 deg
        return pd.DataFrame({"v_m_s": rng.uniform(4.0, 5.0, n),
                             "theta_deg": np.mod(rng.uniform(centre - 20, centre + 20, n), 360)})

    assert 20.0 < widest_gap_cut(band(0.0)["theta_deg"].to_numpy()) < 340.0
    assert samples_agree(band(0.0), band(0.0))
    assert not samples_agree(band(60.0), band(0.0))  # the band moved
    assert not samples_agree(band(0.0).assign(v_m_s=lambda f: f.v_m_s + 0.8), band(0.0))


def test_an_orbit_missing_in_one_run_is_allowed_only_after_a_late_outcome():
    one = pd.DataFrame({"gamma": [1.7] * 4, "initial_condition": [0] * 4,
                        "v_m_s": [4.0] * 4, "theta_deg": [10.0] * 4})
    two = pd.concat([one, one.assign(initial_condition=1)], ignore_index=True)
    periods = {(1.7, 0): 1, (1.7, 1): 1}
    assert orbit_points_drift("t", one, two, periods, periods, lambda key: True, 1e-6, 1e-9) == []
    assert orbit_points_drift("t", one, two, periods, periods, lambda key: False, 1e-6, 1e-9)


def attractor_rows(**columns):
    base = {"gamma": [1.7, 1.7, 1.8], "initial_condition": [0, 1, 0],
            "theta0_deg": [45.0, 90.0, 45.0], "v0_m_s": [3.0, 3.0, 3.0],
            "attractor": ["chaotic", "sticking", "period2"], "period": [0, 0, 2],
            "lyapunov_per_impact": [0.30, np.nan, -0.4],
            "lyapunov_se_per_impact": [0.01, np.nan, 1e-12],
            "stuck_at_impact": [-1, 12, -1]}
    return pd.DataFrame({**base, **columns})


def test_late_outcomes_may_change_and_early_ones_may_not():
    committed = attractor_rows()
    tables = RunTables({}, {}, {})

    def drift(fresh):
        return table_drift("bifurcation", "attractors.csv", fresh, committed, tables)

    # the chaotic orbit stuck late in the other run: allowed; at impact 12: not late
    late_stick = attractor_rows(attractor=["sticking", "sticking", "period2"],
                                lyapunov_per_impact=[np.nan, np.nan, -0.4],
                                lyapunov_se_per_impact=[np.nan, np.nan, 1e-12],
                                stuck_at_impact=[LATE_IMPACT + 5, 12, -1])
    assert drift(late_stick) == []
    early_stick = late_stick.assign(stuck_at_impact=[LATE_IMPACT - 5, 12, -1])
    assert any("attractor" in line for line in drift(early_stick))
    assert any("stuck_at_impact" in line for line in drift(attractor_rows(
        stuck_at_impact=[-1, 13, -1])))
    # a chaotic exponent within 6 combined errors (0.01 each: 0.085), not beyond
    assert drift(attractor_rows(lyapunov_per_impact=[0.37, np.nan, -0.4])) == []
    assert drift(attractor_rows(lyapunov_per_impact=[0.40, np.nan, -0.4]))
    # a periodic orbit's exponent keeps the reproduction tolerance
    assert drift(attractor_rows(lyapunov_per_impact=[0.30, np.nan, -0.4001]))


def test_sweep_fractions_may_move_by_the_undecided_points_last_bits_decide():
    committed = pd.DataFrame({"point": [0, 1], "alpha": [0.5, 0.5], "basin_points": [1600, 1600],
                              "fraction_period1": [0.9, 0.0], "fraction_sticking": [0.1, 0.4],
                              "fraction_undecided": [0.0, 0.6], "basin_entropy": [0.1, 0.6],
                              "boundary_basin_entropy": [0.5, 0.7], "boundary_boxes": [10, 60]})
    tables = RunTables({}, {}, {"measures": {"entropy_box": 5}})

    def drift(fresh):
        return table_drift("sweep", "sweep.csv", fresh, committed, tables)

    undecided = 0.6 * 1600
    flips = int(allowed_flips(undecided)[()])  # 1 + 4 sqrt(960) = 124
    assert flips == 124
    moved = committed.copy()
    moved.loc[1, ["fraction_sticking", "fraction_undecided"]] = [0.4 + flips / 1600,
                                                                 0.6 - flips / 1600]
    moved.loc[1, "basin_entropy"] += 0.05
    assert drift(moved) == []
    moved.loc[1, ["fraction_sticking", "fraction_undecided"]] = [0.5, 0.5]  # 160 points
    assert any("fraction_sticking" in line for line in drift(moved))
    decided = committed.copy()  # nothing undecided: one point (on a boundary) may flip
    decided.loc[0, ["fraction_period1", "fraction_sticking"]] = [0.9 - 1 / 1600, 0.1 + 1 / 1600]
    assert drift(decided) == []
    decided.loc[0, ["fraction_period1", "fraction_sticking"]] = [0.9 - 2 / 1600, 0.1 + 2 / 1600]
    assert drift(decided)
    entropy = committed.assign(basin_entropy=[0.1 + 0.01, 0.6])  # beyond what 1 flip can do
    assert any("basin_entropy" in line for line in drift(entropy))
    other = committed.assign(alpha=[0.5, 0.51])
    assert any("alpha" in line for line in drift(other))


def test_the_onset_of_chaos_moves_only_with_a_late_outcome(small_bifurcation):
    attractors = small_bifurcation["attractors.csv"]
    thresholds = small_bifurcation["thresholds.csv"]
    onset = thresholds.threshold == "first_chaotic_orbit"
    first = float(thresholds.loc[onset, "located_gamma"].iloc[0])
    later = thresholds.copy()
    later.loc[onset, "located_gamma"] = first + 0.01
    same = RunTables({"attractors.csv": attractors}, {"attractors.csv": attractors}, {})
    assert table_drift("bifurcation", "thresholds.csv", later, thresholds, same)
    at_first = np.isclose(attractors.gamma, first) & (attractors.attractor == "chaotic")
    assert at_first.any()
    flipped = attractors.copy()
    flipped.loc[at_first, ["attractor", "stuck_at_impact"]] = ["sticking", 200]
    moved = RunTables({"attractors.csv": flipped}, {"attractors.csv": attractors}, {})
    assert table_drift("bifurcation", "thresholds.csv", later, thresholds, moved) == []
    assert math.isfinite(first)


def test_reproduce_leaves_a_bifurcation_moved_by_ulps_as_committed(tmp_path):
    """The path ``bounce reproduce`` takes (``RunDirectory.commit`` with the reproduction
    rule, the previous run's tables read from its folder): a run whose chaotic orbits went
    their own way after a last-bit difference leaves every file as it was."""
    from bounce_cli.paper.reproduce import tables_agree
    from bounce_cli.runtime.artifacts import RunDirectory

    out = tmp_path / "bifurcation"

    def commit(**change):
        result = bounce_cli.run("bifurcation", set={**SMALL_BIFURCATION, **change})
        run = RunDirectory(out, command="bifurcation", resolved_config={"small": True},
                           overrides=[], config_path=None)
        for name, frame in result.frames.items():
            run.add_csv(name, frame)
        for name, figure in result.figures.items():
            run.add_figure(name, figure)
        run.commit(tables_agree("bifurcation"))
        return run.comparison

    commit()
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.name != "timing.json"}
    comparison = commit(**{"model.g": 9.81 * (1 + 2 * EPS)})
    assert "within tolerance" in comparison.values()
    assert set(comparison.values()) <= {"identical", "within tolerance", "kept"}, comparison
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "timing.json"} == before
    changed = commit(**{"model.alpha": 0.5 * (1 + 1e-6)})
    assert changed["attractors.csv"] == "changed" and changed["bifurcation.png"] != "kept"
