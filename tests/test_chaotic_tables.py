"""The reproduction rules of the tables filled by chaotic orbits (``reproduction/chaotic_tables``):
another machine's last bits are stood in for by moving g by a few ulps (it reaches every
orbit from the first impact, as another libm's sin and cos do), which must be accepted,
while a real change must not be: of the model (alpha or g by 1e-6), and each systematic
change a regression could make to what is compared statistically (chaos lost, exponents 10 %
off, an attractor's velocities 5 % off or phases 10 deg off, basin fractions moved), built
by hand from the committed results."""

import io
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import bounce_cli
from bounce_cli.reproduction.chaotic_tables import (
    LATE_STRETCH,
    aggregate_drift,
    allowed_flips,
    balance_drift,
    cycles_agree,
    late_outcome,
    point_statistics,
)
from bounce_cli.reproduction.reproduce import table_drift, value_drift
from bounce_cli.runtime.artifacts import RunTables

EPS = np.finfo(float).eps
RESULTS = Path(__file__).resolve().parent.parent / "results"
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


def committed(name):
    return {p.name: pd.read_csv(p) for p in sorted((RESULTS / name).glob("*.csv"))}


@pytest.fixture(scope="module")
def small_bifurcation():
    return run_frames("bifurcation", **SMALL_BIFURCATION)


@pytest.mark.slow
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


@pytest.mark.slow
def test_a_racket_period_sweep_moved_by_ulps_is_reproduced():
    """Another swept parameter (the racket period: its column first, gamma second), with an
    intermittent chaotic orbit whose exponent is 14 standard errors off at 3 ulps and an
    orbit that is chaotic in one run and period 32 (the longest looked for) in the other."""
    sweep = {"sweep.parameter": "racket_period", "sweep.start": 0.82, "sweep.stop": 0.84,
             "sweep.num": 11, "initial_conditions.theta0_deg": [45, 90, 135],
             "initial_conditions.v0_m_s": [3, 5, 7], "iterate.transient_impacts": 300,
             "iterate.measured_impacts": 400, "flip.locate": False}
    base = run_frames("bifurcation", **sweep)
    config = {"iterate": {"max_period": 32}}
    for ulps in (1, 3):
        moved = run_frames("bifurcation", **sweep, **{"model.g": 9.81 * (1 + ulps * EPS)})
        assert drift_by_table("bifurcation", moved, base, config) == {t: [] for t in base}


@pytest.mark.parametrize("change", [{"model.alpha": 0.5 * (1 + 1e-6)},
                                    {"model.g": 9.81 * (1 + 1e-6)}])
@pytest.mark.slow
def test_a_real_change_of_the_model_is_a_drift(small_bifurcation, change):
    moved = run_frames("bifurcation", **SMALL_BIFURCATION, **change)
    drift = drift_by_table("bifurcation", moved, small_bifurcation)
    assert drift["attractors.csv"] and drift["bifurcation.csv"], drift


def chaotic_rows(frames):
    attractors = frames["attractors.csv"]
    return attractors.attractor == "chaotic"


@pytest.mark.slow
def test_chaos_lost_is_a_drift_though_each_orbit_may_stick_late():
    """Every chaotic orbit of the committed diagram stuck at impact 999 instead: each one is
    a late outcome, but all going one way is not a last bit's reshuffling."""
    frames = committed("bifurcation")
    fresh = dict(frames)
    attractors = frames["attractors.csv"].copy()
    lost = chaotic_rows(frames)
    assert lost.sum() > 100
    attractors.loc[lost, ["attractor", "stuck_at_impact"]] = ["sticking", 999]
    attractors.loc[lost, ["lyapunov_per_impact", "lyapunov_se_per_impact"]] = np.nan
    fresh["attractors.csv"] = attractors
    drift = drift_by_table("bifurcation", fresh, frames)["attractors.csv"]
    assert any("late outcomes" in line for line in drift), drift
    few = frames["attractors.csv"].copy()  # 3 orbits only: a last bit's reshuffling
    three = np.flatnonzero(lost)[:3]
    few.loc[three, ["attractor", "stuck_at_impact"]] = ["sticking", 999]
    few.loc[three, ["lyapunov_per_impact", "lyapunov_se_per_impact"]] = np.nan
    fresh["attractors.csv"] = few
    assert drift_by_table("bifurcation", fresh, frames)["attractors.csv"] == []


@pytest.mark.slow
def test_chaotic_exponents_ten_percent_off_are_a_drift():
    frames = committed("bifurcation")
    fresh = dict(frames)
    chaotic = chaotic_rows(frames)
    attractors = frames["attractors.csv"].copy()
    attractors.loc[chaotic, "lyapunov_per_impact"] *= 1.1
    fresh["attractors.csv"] = attractors
    drift = drift_by_table("bifurcation", fresh, frames)["attractors.csv"]
    assert any("lyapunov_per_impact" in line for line in drift), drift
    # scattered within their errors instead (+-1 standard error, alternately): accepted
    jitter = frames["attractors.csv"].copy()
    signs = np.where(np.arange(chaotic.sum()) % 2, 1.0, -1.0)
    jitter.loc[chaotic, "lyapunov_per_impact"] += signs * jitter.loc[
        chaotic, "lyapunov_se_per_impact"]
    fresh["attractors.csv"] = jitter
    assert drift_by_table("bifurcation", fresh, frames)["attractors.csv"] == []


@pytest.mark.slow
@pytest.mark.parametrize("change", ["velocities 5 % higher", "phases 10 deg later"])
def test_an_attractor_moved_is_a_drift(change):
    frames = committed("bifurcation")
    points = frames["bifurcation.csv"].copy()
    chaotic = frames["attractors.csv"][chaotic_rows(frames)]
    on = pd.MultiIndex.from_frame(points[["gamma", "initial_condition"]]).isin(
        pd.MultiIndex.from_frame(chaotic[["gamma", "initial_condition"]]))
    if change.startswith("velocities"):
        points.loc[on, "v_m_s"] *= 1.05
    else:
        points.loc[on, "theta_deg"] = np.mod(points.loc[on, "theta_deg"] + 10.0, 360.0)
    drift = drift_by_table("bifurcation", {**frames, "bifurcation.csv": points},
                           frames)["bifurcation.csv"]
    assert any("aperiodic orbits" in line for line in drift), drift


def test_point_statistics_are_batch_means_of_an_orbits_points():
    rng = np.random.default_rng(1)
    orbit = pd.DataFrame({"v_m_s": rng.normal(4.0, 0.5, 64), "theta_deg": np.full(64, 90.0)})
    means, se = point_statistics([orbit, orbit], centre=4.0)
    batch = orbit.v_m_s.to_numpy().reshape(8, 8).mean(axis=1)
    assert means[0] == pytest.approx(batch.mean(), rel=1e-14)
    assert se[0] == pytest.approx(np.std(np.tile(batch, 2), ddof=1) / 4.0, rel=1e-14)
    assert means[1] == pytest.approx(0.0, abs=1e-15) and means[2] == pytest.approx(1.0)
    assert se[2] == pytest.approx(0.0, abs=1e-15)


def test_the_tests_of_chance():
    assert balance_drift("t", "w", 3, 0) == []  # 3 <= 4 sqrt(3) + 1
    assert balance_drift("t", "w", 40, 0)
    assert balance_drift("t", "w", 60, 45) == []
    rng = np.random.default_rng(2)
    assert aggregate_drift("t", "w", rng.standard_normal(200)) == []
    assert aggregate_drift("t", "w", rng.standard_normal(200) + 1.0)  # one-sided
    assert aggregate_drift("t", "w", rng.standard_normal(200) * 5.0)  # too large
    assert aggregate_drift("t", "w", [14.0, 0.3, -0.5, 0.2, -1.1]) == []  # one outlier


@pytest.mark.slow
def test_a_continuation_diagram_moved_by_ulps_is_reproduced():
    small = {"starts": [{"at": 1.7, "cycles": 1}], "steps.max_period": 4, "range.low": 1.65,
             "range.high": 1.8, "diagram.num": 12, "diagram.transient_impacts": 300}
    base = run_frames("continuation", **small)
    moved = run_frames("continuation", **small, **{"model.g": 9.81 * (1 + 2 * EPS)})
    assert value_drift("continuation", "diagram.csv", moved["diagram.csv"],
                       base["diagram.csv"])
    assert drift_by_table("continuation", moved, base)["diagram.csv"] == []
    alpha = run_frames("continuation", **small, **{"model.alpha": 0.5 * (1 + 1e-5)})
    assert drift_by_table("continuation", alpha, base)["diagram.csv"]


def test_a_diagram_whose_aperiodic_orbits_all_stuck_is_a_drift():
    """Every chaotic orbit of the committed diagram stuck instead (gone from diagram.csv,
    sticking in diagram_orbits.csv): each a late outcome, all one way a drift; 3 of them a
    last bit's reshuffling; gone from diagram.csv alone, the two tables disagree."""
    frames = committed("continuation")
    diagram, orbits = frames["diagram.csv"], frames["diagram_orbits.csv"]
    keys = ["gamma", "initial_condition"]

    def stuck(which):
        gone = orbits.loc[which, keys]
        kept = diagram[~pd.MultiIndex.from_frame(diagram[keys]).isin(
            pd.MultiIndex.from_frame(gone))].reset_index(drop=True)
        ended = orbits.copy()
        ended.loc[which, ["attractor", "period", "stuck_at_impact"]] = ["sticking", 0, 500]
        ended.loc[which, ["lyapunov_per_impact", "lyapunov_se_per_impact"]] = np.nan
        return {**frames, "diagram.csv": kept, "diagram_orbits.csv": ended}

    chaotic = np.flatnonzero(orbits.attractor == "chaotic")
    assert len(chaotic) > 20
    drift = drift_by_table("continuation", stuck(chaotic), frames)
    assert any("late outcomes" in line for line in drift["diagram_orbits.csv"]), drift
    assert drift_by_table("continuation", stuck(chaotic[:3]), frames) == {
        name: [] for name in frames}
    alone = {**stuck(chaotic[:3]), "diagram_orbits.csv": orbits}
    assert any("not those" in line for line in drift_by_table(
        "continuation", alone, frames)["diagram.csv"])


def test_a_periodic_orbit_is_the_same_cycle_from_any_of_its_impacts():
    cycle = pd.DataFrame({"v_m_s": [4.0, 5.0, 6.0] * 4,
                          "theta_deg": [359.9999999, 120.0, 240.0] * 4})
    later = cycle.iloc[2:].reset_index(drop=True)  # the recording starts two impacts later
    assert cycles_agree(later, cycle, 3, 1e-6, 1e-9)
    wrapped = cycle.assign(theta_deg=np.mod(cycle.theta_deg + 2e-7, 360.0))  # across 360
    assert cycles_agree(wrapped, cycle, 3, 1e-6, 1e-9)
    off = later.assign(v_m_s=later.v_m_s.where(later.v_m_s != 5.0, 5.00001))
    assert not cycles_agree(off, cycle, 3, 1e-6, 1e-9)


def attractor_rows(**columns):
    base = {"gamma": [1.7, 1.7, 1.8], "initial_condition": [0, 1, 0],
            "theta0_deg": [45.0, 90.0, 45.0], "v0_m_s": [3.0, 3.0, 3.0],
            "attractor": ["chaotic", "sticking", "period2"], "period": [0, 0, 2],
            "lyapunov_per_impact": [0.30, np.nan, -0.4],
            "lyapunov_se_per_impact": [0.01, np.nan, 1e-12],
            "stuck_at_impact": [-1, 12, -1], "peak_stretch": [600.0, 5.0, 3.0]}
    return pd.DataFrame({**base, **columns})


def test_late_outcomes_may_change_and_early_ones_may_not():
    base = attractor_rows()
    tables = RunTables({}, {}, {})

    def drift(fresh):
        return table_drift("bifurcation", "attractors.csv", fresh, base, tables)

    # the chaotic orbit stuck after its start's perturbations grew by LATE_STRETCH in the
    # other run: allowed; before they grew so much: not late
    late_stick = attractor_rows(attractor=["sticking", "sticking", "period2"],
                                lyapunov_per_impact=[np.nan, np.nan, -0.4],
                                lyapunov_se_per_impact=[np.nan, np.nan, 1e-12],
                                stuck_at_impact=[40, 12, -1],
                                peak_stretch=[LATE_STRETCH + 5, 5.0, 3.0])
    assert drift(late_stick) == []
    early_stick = late_stick.assign(peak_stretch=[LATE_STRETCH - 5, 5.0, 3.0])
    assert any("attractor" in line for line in drift(early_stick))
    # a chaotic transient that ended on a periodic orbit in one run and stuck in the other
    periodic = attractor_rows(attractor=["chaotic", "sticking", "sticking"], period=[0, 0, 0],
                              lyapunov_per_impact=[0.30, np.nan, np.nan],
                              stuck_at_impact=[-1, 12, 38],
                              peak_stretch=[600.0, 5.0, LATE_STRETCH + 8])
    assert drift(periodic)  # committed: period 2 with peak_stretch 3 is not late
    assert table_drift("bifurcation", "attractors.csv", periodic,
                       attractor_rows(peak_stretch=[600.0, 5.0, LATE_STRETCH + 20]),
                       tables) == []
    assert any("stuck_at_impact" in line for line in drift(attractor_rows(
        stuck_at_impact=[-1, 13, -1])))
    # a periodic orbit's exponent: the reproduction tolerance, or within 6 of its errors
    assert drift(attractor_rows(lyapunov_per_impact=[0.30, np.nan, -0.4001]))
    assert drift(attractor_rows(lyapunov_per_impact=[0.30, np.nan, -0.4001],
                                lyapunov_se_per_impact=[0.01, np.nan, 1e-4])) == []
    # a chaotic orbit's: one far off is an intermittent orbit, not a drift
    assert drift(attractor_rows(lyapunov_per_impact=[0.45, np.nan, -0.4])) == []
    # the period at the longest looked for is read as moving (a long or chaotic orbit)
    # (the config's iterate.max_period; the experiment's default, 32, without one)
    long = attractor_rows(attractor=["period32", "sticking", "period2"], period=[32, 0, 2],
                          peak_stretch=[10.0, 5.0, 3.0])
    assert drift(long) == []
    assert table_drift("bifurcation", "attractors.csv", long, base,
                       RunTables({}, {}, {"iterate": {"max_period": 64}}))


def test_tables_of_another_length_are_a_drift_not_a_crash(small_bifurcation):
    shorter = {name: frame.iloc[:-9].reset_index(drop=True) if name == "attractors.csv"
               else frame for name, frame in small_bifurcation.items()}
    drift = drift_by_table("bifurcation", shorter, small_bifurcation)
    assert drift["attractors.csv"]
    # results of a version without peak_stretch: a drift of its columns, not a crash
    older = {**small_bifurcation, "attractors.csv": small_bifurcation["attractors.csv"].drop(
        columns="peak_stretch")}
    assert drift_by_table("bifurcation", small_bifurcation, older)["attractors.csv"]
    # the tables read beside it are then compared value by value (here: unchanged)
    assert drift["bifurcation.csv"] == drift["values.csv"] == drift["thresholds.csv"] == []


def sweep_rows(**columns):
    base = {"point": [0, 1], "alpha": [0.5, 0.5], "basin_points": [1600, 1600],
            "fraction_period1": [0.9, 0.0], "fraction_sticking": [0.1, 0.4],
            "fraction_undecided": [0.0, 0.6], "basin_entropy": [0.1, 0.6],
            "boundary_basin_entropy": [0.5, 0.7], "boundary_boxes": [10, 60]}
    return pd.DataFrame({**base, **columns})


SWEEP_CONFIG = {"measures": {"entropy_box": 5},
                "basin": {"theta0_deg": {"num": 40}, "v0_m_s": {"num": 40}}}


def sweep_drift(fresh, base=None, config=SWEEP_CONFIG):
    return table_drift("sweep", "sweep.csv", fresh, sweep_rows() if base is None else base,
                       RunTables({}, {}, config))


def test_sweep_fractions_may_move_by_the_undecided_points_last_bits_decide():
    undecided = 0.6 * 1600
    flips = int(allowed_flips(undecided)[()])  # 1 + 4 sqrt(960) = 124
    assert flips == 124
    moved = sweep_rows()
    moved.loc[1, ["fraction_sticking", "fraction_undecided"]] = [0.4 + flips / 1600,
                                                                 0.6 - flips / 1600]
    moved.loc[1, "basin_entropy"] += 0.4  # 124 flips x 2 ln 25 / 25 / 64 boxes = 0.499
    assert sweep_drift(moved) == []
    moved.loc[1, "basin_entropy"] += 0.2
    assert any("basin_entropy" in line for line in sweep_drift(moved))
    moved.loc[1, ["fraction_sticking", "fraction_undecided"]] = [0.5, 0.5]  # 160 points
    assert any("fraction_sticking" in line for line in sweep_drift(moved))
    decided = sweep_rows()  # nothing undecided: one point (on a boundary) may flip
    decided.loc[0, ["fraction_period1", "fraction_sticking"]] = [0.9 - 1 / 1600, 0.1 + 1 / 1600]
    assert sweep_drift(decided) == []
    decided.loc[0, ["fraction_period1", "fraction_sticking"]] = [0.9 - 2 / 1600, 0.1 + 2 / 1600]
    assert sweep_drift(decided)
    # one flip among 10 boundary boxes, 3 outcomes: at most (2 ln 25 / 25 + ln 3) / (10 - 1)
    # = 0.151
    assert sweep_drift(sweep_rows(boundary_basin_entropy=[0.5 + 0.14, 0.7])) == []
    assert sweep_drift(sweep_rows(boundary_basin_entropy=[0.5 + 0.16, 0.7]))
    assert sweep_drift(sweep_rows(boundary_boxes=[12, 60]))  # 1 flip: one box more at most
    assert any("alpha" in line for line in sweep_drift(sweep_rows(alpha=[0.5, 0.51])))


def test_basin_fractions_moved_one_way_at_every_point_are_a_drift():
    """4 percentage points from undecided to sticking at every point with many undecided
    points, within each point's allowance: one-sided, so a drift."""
    frames = committed("sweep")
    table = frames["sweep.csv"]
    config = {"measures": {"entropy_box": 5},
              "basin": {"theta0_deg": {"num": 40}, "v0_m_s": {"num": 40}}}
    moved = table.copy()
    many = moved.fraction_undecided > 0.3
    assert many.sum() >= 5
    moved.loc[many, "fraction_undecided"] -= 0.04
    moved.loc[many, "fraction_sticking"] += 0.04
    assert (0.04 * 1600 < allowed_flips(1600 * table.fraction_undecided[many])).all()
    drift = table_drift("sweep", "sweep.csv", moved, table, RunTables({}, {}, config))
    assert any("fraction_sticking" in line and "one-sided" in line for line in drift), drift
    assert not any("1 + 4 sqrt" in line for line in drift)  # no point beyond its allowance


@pytest.mark.slow
def test_a_sweep_with_the_uncertainty_exponent_moved_by_ulps_is_reproduced():
    small = {"sweep.x": {"parameter": "alpha", "start": 0.3, "stop": 0.4, "num": 2},
             "sweep.y": {"parameter": "ac_g", "start": -1.6, "stop": -1.5, "num": 2},
             "basin.theta0_deg": {"start": 0, "stop": 360, "num": 30},
             "basin.v0_m_s": {"start": 0, "stop": 10, "num": 30},
             "measures.uncertainty": True, "measures.samples": 300}
    config = {"measures": {"entropy_box": 5, "samples": 300},
              "basin": {"theta0_deg": {"num": 30}, "v0_m_s": {"num": 30}}}
    base = run_frames("sweep", **small)
    moved = run_frames("sweep", **small, **{"model.g": 9.81 * (1 + EPS)})
    assert value_drift("sweep", "uncertainty.csv", moved["uncertainty.csv"],
                       base["uncertainty.csv"])
    assert drift_by_table("sweep", moved, base, config) == {t: [] for t in base}
    shifted = moved["uncertainty.csv"].assign(
        uncertain_fraction=lambda f: f.uncertain_fraction + 0.1)
    assert drift_by_table("sweep", {**moved, "uncertainty.csv": shifted}, base,
                          config)["uncertainty.csv"]


def test_the_onset_of_chaos_moves_only_with_a_late_outcome(small_bifurcation):
    attractors = small_bifurcation["attractors.csv"]
    thresholds = small_bifurcation["thresholds.csv"]
    onset = thresholds.threshold == "first_chaotic_orbit"
    first = float(thresholds.loc[onset, "located_gamma"].iloc[0])
    assert math.isfinite(first)
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


@pytest.mark.slow  # 2-3 s
def test_reproduce_leaves_a_bifurcation_moved_by_ulps_as_committed(tmp_path):
    """The path ``bounce reproduce`` takes (``RunDirectory.commit`` with the reproduction
    rule, the previous run's tables read from its folder): a run whose chaotic orbits went
    their own way after a last-bit difference leaves every file as it was; a run that
    changed rewrites all its tables, so that the folder never holds two runs' tables."""
    from bounce_cli.reproduction.reproduce import tables_agree
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
        return run.comparison, result.frames

    commit()
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.name != "timing.json"}
    comparison, _ = commit(**{"model.g": 9.81 * (1 + 2 * EPS)})
    assert "within tolerance" in comparison.values()
    assert set(comparison.values()) <= {"identical", "within tolerance", "kept"}, comparison
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "timing.json"} == before
    changed, frames = commit(**{"model.alpha": 0.5 * (1 + 1e-6)})
    assert changed["attractors.csv"] == "changed" and changed["bifurcation.png"] != "kept"
    for name, frame in frames.items():  # every table is this run's
        assert (out / name).read_bytes() == frame.to_csv(index=False).encode(), name


@pytest.mark.parametrize("case", ["alpha sweep: transients ending on cycles 6 or 3",
                                  "one start recording 8 impacts",
                                  "continuation diagram with exact sticking",
                                  pytest.param("sweep with exact sticking",
                                               marks=pytest.mark.slow)])  # 3 s
@pytest.mark.slow
def test_other_settings_moved_by_ulps_are_reproduced(case):
    """Settings a review found refused before (each at the ulps it was refused at): chaotic
    transients that end on one cycle, another or the racket; recordings of one batch (no
    standard error); a chaotic orbit in one run locked (a chatter cycle) in the other; with
    exact sticking, every stuck ball of a sweep point takes the one released ball's fate."""
    name, settings, ulps = {
        "alpha sweep: transients ending on cycles 6 or 3": ("bifurcation", {
            "initial_conditions.theta0_deg": [45, 90, 135], "initial_conditions.v0_m_s": [3, 5, 7],
            "iterate.transient_impacts": 300, "iterate.measured_impacts": 400,
            "flip.locate": False, "sweep.parameter": "alpha", "sweep.start": 0.72,
            "sweep.stop": 0.76, "sweep.num": 3}, (-3, -2)),
        "one start recording 8 impacts": ("bifurcation", {
            "initial_conditions.theta0_deg": [90], "initial_conditions.v0_m_s": [5],
            "iterate.recorded_impacts": 8, "iterate.max_period": 4,
            "iterate.transient_impacts": 300, "iterate.measured_impacts": 400,
            "flip.locate": False, "sweep.start": 1.70, "sweep.stop": 2.0, "sweep.num": 31},
            (-2, 3)),
        "continuation diagram with exact sticking": ("continuation", {
            "starts": [{"at": 1.7, "cycles": 1}], "steps.max_period": 4, "range.low": 1.5,
            "range.high": 1.9, "diagram.num": 20, "diagram.transient_impacts": 300,
            "diagram.min_hop_s": 0}, (-1, 1)),
        "sweep with exact sticking": ("sweep", {
            "sweep.x": {"parameter": "alpha", "start": 0.4, "stop": 0.7, "num": 2},
            "sweep.y": {"parameter": "ac_g", "start": -1.6, "stop": -1.0, "num": 3},
            "basin.theta0_deg": {"start": 0, "stop": 360, "num": 40},
            "basin.v0_m_s": {"start": 0, "stop": 10, "num": 40}, "classify.min_hop_s": 0},
            (-1, 1)),
    }[case]
    config = _nested(settings)
    base = run_frames(name, **settings)
    for k in ulps:
        moved = run_frames(name, **settings, **{"model.g": 9.81 * (1 + k * EPS)})
        assert drift_by_table(name, moved, base, config) == {t: [] for t in base}, k


def _nested(settings):
    """Dotted settings as the nested config run.json holds."""
    out: dict = {}
    for key, value in settings.items():
        *parents, last = key.split(".")
        block = out
        for part in parents:
            block = block.setdefault(part, {})
        block[last] = value
    return out


@pytest.mark.parametrize("regression", [
    "exponents' standard errors x10", "impacts renumbered", "chaotic orbits cut to 16 impacts",
    "boundary entropy 0 where many points are late"])
@pytest.mark.slow
def test_regressions_in_what_the_statistical_rules_read_are_drifts(regression):
    name = "sweep" if "entropy" in regression else "bifurcation"
    frames = committed(name)
    config = {"measures": {"entropy_box": 5},
              "basin": {"theta0_deg": {"num": 40}, "v0_m_s": {"num": 40}}}
    fresh = dict(frames)
    if regression == "exponents' standard errors x10":
        fresh["attractors.csv"] = frames["attractors.csv"].assign(
            lyapunov_se_per_impact=lambda f: f.lyapunov_se_per_impact * 10)
    elif regression == "impacts renumbered":
        fresh["bifurcation.csv"] = frames["bifurcation.csv"].assign(impact=lambda f: f.impact + 1)
    elif regression == "chaotic orbits cut to 16 impacts":
        points = frames["bifurcation.csv"]
        keys = ["gamma", "initial_condition"]
        chaotic = frames["attractors.csv"].loc[chaotic_rows(frames), keys]
        on = pd.MultiIndex.from_frame(points[keys]).isin(pd.MultiIndex.from_frame(chaotic))
        cut = on & (points.groupby(keys).cumcount() >= 16).to_numpy()
        fresh["bifurcation.csv"] = points[~cut].reset_index(drop=True)
    else:
        table = frames["sweep.csv"].copy()
        many = table.boundary_boxes <= allowed_flips(table.points_decided_late)
        assert many.sum() >= 5
        table.loc[many, "boundary_basin_entropy"] = 0.0
        fresh["sweep.csv"] = table
    drift = drift_by_table(name, fresh, frames, config)
    assert any(drift.values()), drift
