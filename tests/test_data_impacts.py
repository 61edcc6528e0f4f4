"""The impacts table reader (bounce_cli/data/impacts.py): a lab's own file or ours, checked with
one-line errors naming the file and the column, row or trial."""

import numpy as np
import pandas as pd
import pytest

from bounce_cli.runtime.config import ConfigError
from bounce_cli.model.params import ModelParams, circular_mean
from bounce_cli.analysis.data_stats import perturbation_schedule, simulate_impacts
from bounce_cli.data.impacts import (
    EVENT_COLUMNS,
    REQUIRED_COLUMNS,
    impacts_frame,
    read_impacts,
)

PAPER = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)


@pytest.fixture(scope="module")
def table():
    alpha = perturbation_schedule(3, 30, 10, 0.5, [(0.4, 0.45), (0.55, 0.6)], seed=1)
    sim = simulate_impacts(PAPER, 0.01, 0.01, 3, 30, seed=2, alpha=alpha)
    return impacts_frame(sim, PAPER)


def write(tmp_path, frame, name="impacts.csv"):
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def test_simulated_table_has_the_fixed_columns_and_reads_back(table, tmp_path):
    assert list(table.columns) == [*REQUIRED_COLUMNS, *EVENT_COLUMNS, "g_m_s2"]
    impacts = read_impacts(write(tmp_path, table), needs=("alpha", "perturbed", "ball_apex_m"))
    f = impacts.frame
    assert impacts.trials == ["1", "2", "3"]
    assert f["perturbed"].dtype == bool and f["perturbed"].sum() == 3 * 2
    np.testing.assert_allclose(f["theta_rad"], table["theta_rad"])
    # the synthetic lab's columns follow their definitions
    assert (f["theta_deg"] >= 0).all() and (f["theta_deg"] < 360).all()
    np.testing.assert_allclose(f["racket_acc_g"], -0.30 * PAPER.omega**2 * np.sin(f["theta_rad"])
                               / 9.81)
    t = table[table.trial == 1]
    np.testing.assert_allclose(t["hop_s"].to_numpy()[:-1], np.diff(t["t_s"].to_numpy()))


def test_a_labs_file_in_another_order_with_degrees_only(table, tmp_path):
    lab = table.drop(columns=["theta_rad"]).sample(frac=1.0, random_state=3)
    lab["trial"] = lab["trial"].map({1: "S01-b", 2: "S01-a", 3: "S01-c"})
    impacts = read_impacts(write(tmp_path, lab))
    f = impacts.frame
    for _trial, rows in impacts.by_trial():
        assert list(rows["k"]) == sorted(rows["k"])
    np.testing.assert_allclose(np.sort(f["theta_rad"]), np.sort(table["theta_rad"]), rtol=1e-12)


def test_segments_break_at_a_missing_impact(table, tmp_path):
    gap = table.drop(index=table.index[(table.trial == 1) & (table.k == 12)])
    impacts = read_impacts(write(tmp_path, gap))
    lengths = [len(rows) for _, rows in impacts.segments()]
    assert lengths == [12, 17, 30, 30]


@pytest.mark.parametrize("change, needles", [
    (lambda f: f.drop(columns=["v_m_s"]), ["missing column(s) v_m_s", "not an impacts table"]),
    (lambda f: f.drop(columns=["theta_rad", "theta_deg"]), ["theta_rad (or theta_deg)"]),
    (lambda f: f.drop(columns=["ball_apex_m"]), ["missing column ball_apex_m",
                                                  "SD of ball amplitude"]),
    (lambda f: f.drop(columns=["alpha"]), ["missing column alpha", "perturbations"]),
    (lambda f: f.assign(v_m_s=f["v_m_s"].where(f.index != 4, np.nan)),
     ["column v_m_s", "data row 5", "trial 1"]),
    (lambda f: pd.concat([f, f.iloc[[3]]]), ["trial 1", "k = 3 appears twice"]),
    (lambda f: f[(f.trial != 2) | (f.k < 3)], ["trial 2", "3 impacts", "fewer than the 5"]),
    (lambda f: f.assign(perturbed="maybe"), ["column perturbed", "True/False"]),
    (lambda f: f.assign(racket_period_s=-1.0), ["racket_period_s", "must be > 0"]),
])
def test_bad_tables_are_one_line_errors(table, tmp_path, change, needles):
    path = write(tmp_path, change(table))
    with pytest.raises(ConfigError) as err:
        read_impacts(path, needs=("ball_apex_m", "alpha", "perturbed", "racket_period_s"),
                     command="x", min_bounces=5)
    message = str(err.value)
    assert "\n" not in message and str(path) in message
    for needle in needles:
        assert needle in message


def test_a_short_trial_is_left_out_with_a_warning_where_asked(table, tmp_path):
    """A study's unit (``drop_short``): one short recording costs that trial, not the unit's
    analysis; the other trials keep their numbers in the series. A file given with --data:
    an error naming the setting to lower. All trials short: an error either way."""
    short = table[(table.trial != 1) | (table.k < 3)]
    warned = []
    impacts = read_impacts(("s1", short), command="learning --data", min_bounces=5,
                           min_bounces_key="min_bounces", drop_short=warned.append)
    assert impacts.trials == ["2", "3"] and len(impacts.frame) == 60
    assert [impacts.trial_number(t) for t in impacts.trials] == [2, 3]
    assert warned == ["trial 1: 3 impacts, fewer than the 5 bounce learning --data needs per "
                      "trial: left out (lower min_bounces to keep it)"]
    with pytest.raises(ConfigError, match="trial 1: 3 impacts.*or lower min_bounces"):
        read_impacts(write(tmp_path, short), command="learning --data", min_bounces=5,
                     min_bounces_key="min_bounces")
    with pytest.raises(ConfigError, match="trial 1: 30 impacts"):
        read_impacts(("s1", table), min_bounces=31, drop_short=warned.append)
    assert read_impacts(("s1", table)).trial_number("3") == 3  # nothing left out


def test_a_recording_given_as_impacts_says_to_extract_it_first(tmp_path):
    recording = pd.DataFrame({"trial": 1, "t_s": [0.0, 0.01], "racket_x_m": 0.0,
                              "ball_x_m": [0.5, 0.49]})
    with pytest.raises(ConfigError, match="not an impacts table.*bounce extract --data it"):
        read_impacts(write(tmp_path, recording))


def test_unreadable_files(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        read_impacts(tmp_path / "nope.csv")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(ConfigError, match="cannot read as CSV"):
        read_impacts(empty)


def test_circular_mean_across_zero():
    assert circular_mean(np.radians([350.0, 10.0])) == pytest.approx(0.0, abs=1e-12) or \
        circular_mean(np.radians([350.0, 10.0])) == pytest.approx(2 * np.pi, abs=1e-12)
    assert np.degrees(circular_mean(np.radians([40.0, 44.0]))) == pytest.approx(42.0)


@pytest.mark.parametrize("cell, shown", [("n/a", "got 'n/a'"), ("", "got an empty cell"),
                                         ("fast", "got 'fast'")])
def test_a_bad_cell_is_shown_as_the_file_holds_it(tmp_path, cell, shown):
    """Errors name the cell as written, never numpy's repr (np.float64(nan))."""
    from bounce_cli.runtime.config import ConfigError
    from bounce_cli.data.impacts import read_impacts

    rows = ["trial,k,t_s,theta_rad,v_m_s", "1,0,0.0,0.7,4.5", f"1,1,0.92,0.7,{cell}",
            "1,2,1.84,0.7,4.5"]
    path = tmp_path / "i.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(ConfigError) as info:
        read_impacts(path)
    assert shown in str(info.value) and "np.float64" not in str(info.value)
    assert "column v_m_s" in str(info.value)


def test_perturbed_is_checked_wherever_present_and_yes_no_is_read(table, tmp_path):
    """A new-user review: `perturbed` written yes/no was read as never perturbed by acf and
    learning (only impulse, which needs the column, checked it)."""
    yes_no = table.assign(perturbed=np.where(table["perturbed"], "yes", "no"))
    read = read_impacts(write(tmp_path, yes_no))  # no analysis asks for the column
    np.testing.assert_array_equal(read.frame.sort_values(["trial", "k"])["perturbed"],
                                  table.sort_values(["trial", "k"])["perturbed"])
    assert read.frame["perturbed"].any()
    with pytest.raises(ConfigError, match="column perturbed"):
        read_impacts(write(tmp_path, table.assign(perturbed="maybe"), "maybe.csv"))


def test_trial_labels_are_read_as_written(table, tmp_path):
    """"01" and "1" are two trials (pandas would read both as the number 1 and merge them)."""
    two = table[table.trial.isin([1, 2])].copy()
    two["trial"] = np.where(two["trial"] == 1, "01", "1")
    read = read_impacts(write(tmp_path, two))
    assert read.trials == ["01", "1"]
    assert [len(rows) for _, rows in read.by_trial()] == [30, 30]


def test_phases_in_degrees_under_theta_rad_are_refused(table, tmp_path):
    degrees = table.drop(columns="theta_deg").assign(theta_rad=table["theta_deg"])
    with pytest.raises(ConfigError, match="beyond 2 pi: degrees"):
        read_impacts(write(tmp_path, degrees))


def test_theta_rad_and_theta_deg_must_agree(table, tmp_path):
    """Both columns given: they are one phase in two units (theta_deg was silently ignored)."""
    read_impacts(write(tmp_path, table, "both.csv"))  # ours agree
    off = table.assign(theta_deg=table["theta_deg"] + 5.0)
    with pytest.raises(ConfigError, match="theta_rad and theta_deg disagree"):
        read_impacts(write(tmp_path, off, "off.csv"))


# -- the local fits' least squares: normal equations, SVD where they would lose digits -------
def _svd_least_squares(design, y):
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return coef, np.linalg.pinv(design.T @ design)


def test_least_squares_agrees_with_svd_on_the_local_fits_designs():
    """The normal equations of the extraction's fits (scaled-time polynomials of degree
    0-4, a line in seconds) agree with lstsq/pinv within 1e-11 relative."""
    from bounce_cli.data.extraction import least_squares

    rng = np.random.default_rng(7)
    for trial in range(300):
        n = int(rng.integers(3, 80))
        if trial % 3 == 0:
            dt = np.sort(rng.uniform(-0.05, 0.6, n))
            design = np.column_stack([np.ones(n), dt])
        else:
            degree = int(rng.integers(0, min(5, n)))
            s = np.sort(rng.uniform(-1, 1, n))
            design = np.vander(s, degree + 1, increasing=True)
        y = rng.normal(size=n) + 3.0 * design[:, -1]
        coef, inverse = least_squares(design, y)
        ref_coef, ref_inverse = _svd_least_squares(design, y)
        scale = np.abs(ref_coef).max()
        assert np.allclose(coef, ref_coef, rtol=1e-11, atol=1e-11 * scale), trial
        assert np.allclose(inverse, ref_inverse, rtol=1e-11,
                           atol=1e-11 * np.abs(ref_inverse).max()), trial


@pytest.mark.parametrize("case", ["flight", "one time", "far from zero", "two samples"])
def test_the_closed_form_line_is_least_squares_on_the_columns_one_and_x(case):
    """least_squares_line (the flights' fits) is least_squares on (1, x): the same
    coefficients and (X'X)^-1 within 1e-11, the fallback where X'X is singular (one sample
    time) or ill-conditioned (times far from their reference) included."""
    from bounce_cli.data.extraction import least_squares, least_squares_line

    rng = np.random.default_rng(3)
    for _ in range(100):
        n = 2 if case == "two samples" else int(rng.integers(3, 80))
        if case == "one time":
            x = np.full(n, 0.3)
        elif case == "far from zero":
            x = 1e4 + np.sort(rng.uniform(0.0, 0.5, n))
        else:
            x = np.sort(rng.uniform(-0.05, 0.6, n))
        y = 2.0 - 4.0 * x + rng.normal(size=n)
        coef, inverse = least_squares_line(x, y)
        ref_coef, ref_inverse = least_squares(np.column_stack([np.ones(n), x]), y)
        assert np.allclose(coef, ref_coef, rtol=1e-11, atol=1e-11 * np.abs(ref_coef).max())
        assert np.allclose(inverse, ref_inverse, rtol=1e-11,
                           atol=1e-11 * np.abs(ref_inverse).max())


@pytest.mark.parametrize("case", ["singular", "ill-conditioned"])
def test_least_squares_falls_back_to_svd_where_the_normal_equations_lose_digits(case):
    from bounce_cli.data.extraction import GRAM_CONDITION_LIMIT, least_squares

    s = np.linspace(0.9995, 1.0, 12)
    design = (np.column_stack([np.ones(12), s, s]) if case == "singular"
              else np.vander(s, 3, increasing=True))
    gram = design.T @ design
    assert np.linalg.cond(gram) > GRAM_CONDITION_LIMIT
    y = np.sin(7 * s)
    coef, inverse = least_squares(design, y)
    ref_coef, ref_inverse = _svd_least_squares(design, y)
    assert np.allclose(coef, ref_coef, rtol=1e-12, atol=0)
    assert np.allclose(inverse, ref_inverse, rtol=1e-12, atol=0)


@pytest.mark.parametrize("labels, ordered", [
    (["3", "1", "10"], ["1", "3", "10"]),  # numbers, e.g. sorted as text or files glued
    (["03", "1", "-2"], ["-2", "1", "03"]),
    # labels with numbers in them need not be in time order by them (a review: conditions
    # recorded as cond3, cond1, ...; dates 28.12.2025_1 before 05.01.2026_1; amp0.25 after
    # amp0.3 where the numbers were split at the point): the file's order
    (["T3", "T1", "T10"], ["T3", "T1", "T10"]),
    (["cond3", "cond1", "cond2"], ["cond3", "cond1", "cond2"]),
    (["28.12.2025_1", "05.01.2026_1", "05.01.2026_2"],
     ["28.12.2025_1", "05.01.2026_1", "05.01.2026_2"]),
    (["post", "pre", "mid"], ["post", "pre", "mid"]),  # words: the file's order
    (["2", "x", "1"], ["2", "x", "1"]),  # numbers and words: the file's order
])
def test_trials_are_in_the_order_of_their_numbers(table, tmp_path, labels, ordered):
    """Trials were in the file's order of first appearance, whatever their labels: a lab's
    file sorted as text (1, 10, 2) or glued from several files numbered trial 3 before trial
    1, and learning's trend over trials (trial_number) was fitted in that order, silently
    (an AC trend of -0.0137 g per trial read as +0.0022). Whole numbers are ordered by
    their value, as a study's manifest orders numbered recordings; other labels keep the
    file's order, and ``listed`` says where the order differs from the file's."""
    frame = table.copy()
    frame["trial"] = frame["trial"].map(dict(zip([1, 2, 3], labels)))
    read = read_impacts(write(tmp_path, frame))
    assert read.trials == ordered
    assert read.listed == (() if ordered == labels else tuple(labels))
    assert [read.trial_number(t) for t in ordered] == [1, 2, 3]
    for label, rows in read.by_trial():
        np.testing.assert_array_equal(rows["v_m_s"], frame[frame.trial == label]["v_m_s"])


@pytest.mark.parametrize("prefix, commented", [("\ufeff# impacts of S07\n", False),
                                               ("# impacts of S07\n\n# S07\n", False),
                                               ("# impacts of S07\n", True)])
def test_an_impacts_table_after_an_export_s_notes(table, tmp_path, prefix, commented):
    """Notes before the header, after a byte-order mark or with a blank line among them, and
    a header written as a comment ('#trial,k,...'), read as the plain table."""
    body = table.to_csv(index=False)
    path = tmp_path / "impacts.csv"
    path.write_text(prefix + ("#" if commented else "") + body, encoding="utf-8")
    read = read_impacts(path).frame
    plain = read_impacts(write(tmp_path, table, "plain.csv")).frame
    pd.testing.assert_frame_equal(read, plain)
