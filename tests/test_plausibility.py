"""Unit slips do not pass silently: racket amplitudes and periods outside what a person can do
(``bounce_cli.data.plausibility``, the one place of the ranges) are warned about, naming the
slip."""

import pandas as pd
import pytest

from bounce_cli.data.plausibility import (
    HUMAN_RACKET_AMPLITUDE_M,
    HUMAN_RACKET_PERIOD_S,
    racket_warnings,
)


def warnings_of(result) -> list[str]:
    return [line for line in result.stderr.splitlines() if line.startswith("bounce: warning:")]


def test_the_paper_s_rackets_are_plausible_and_slips_are_named():
    # sections 5-7: 0.065-0.30 m at 0.53-0.92 s, well inside
    assert HUMAN_RACKET_AMPLITUDE_M[0] < 0.065 and 0.30 < HUMAN_RACKET_AMPLITUDE_M[1]
    assert HUMAN_RACKET_PERIOD_S[0] < 0.53 and 0.92 < HUMAN_RACKET_PERIOD_S[1]
    assert racket_warnings([0.065, 0.30], [0.53, 0.92], "a", "p") == []
    (amplitude,) = racket_warnings(300.0, 0.92, "a", "p")
    assert "millimetres (0.3 m) typed for metres?" in amplitude
    (period,) = racket_warnings(0.3, 920.0, "a", "p")
    assert "milliseconds (0.92 s) typed for seconds?" in period
    (both,) = racket_warnings(30.0, 0.9, "a", "p")  # 30 mm and 30 cm are both a racket
    assert "millimetres (0.03 m) or centimetres (0.3 m)" in both
    (far,) = racket_warnings(1e6, 0.9, "a", "p")
    assert far.endswith("check the units")


def test_fixed_point_warns_of_millimetres_typed_for_metres(cli):
    """`fixed-point --set model.racket_amplitude=300` answered AC -1426 g without a word."""
    result = cli("fixed-point", "--set", "model.racket_amplitude=300", "--json")
    assert result.exit_code == 0, result.output
    (line,) = warnings_of(result)
    assert "model.racket_amplitude: racket amplitude 300 m is outside what a person can do" in (
        line)
    assert "millimetres (0.3 m) typed for metres?" in line
    assert warnings_of(cli("fixed-point", "--json")) == []


def test_regression_warns_of_trial_amplitudes_in_mm_under_an_m_column(tmp_path, cli):
    """a_r_m in mm gives eq. 15's slope 305 m/s^2 against 0.30: now with a warning naming it."""
    path = tmp_path / "trials.csv"
    pd.DataFrame({"a_r_m": [100.0, 150.0, 210.0, 280.0], "tau_s": [0.5, 0.6, 0.7, 0.8],
                  "alpha": 0.5, "g": 9.81}).to_csv(path, index=False)
    result = cli("regression", "--data", path, "--out", tmp_path / "o", "--quiet")
    assert result.exit_code == 0, result.output
    (line,) = warnings_of(result)
    assert f"data: {path}: column a_r_m: racket amplitude 4 of 4 values outside" in line
    assert "millimetres (0.28 m) typed for metres?" in line


@pytest.mark.parametrize("column,scale,needle", [
    ("racket_amplitude_m", 1000.0, "millimetres (0.11 m) typed for metres?"),
    ("racket_period_s", 1000.0, "milliseconds (0.6 s) typed for seconds?"),
])
@pytest.mark.slow
def test_an_impacts_table_in_the_wrong_unit_is_warned_about(tmp_path, cli, column, scale,
                                                            needle):
    from test_data_parameters import lab_table

    path = lab_table(tmp_path)
    frame = pd.read_csv(path)
    frame[column] = frame[column] * scale
    frame.to_csv(path, index=False)
    result = cli("learning", "--data", path, "--out", tmp_path / "o", "--quiet")
    lines = [line for line in warnings_of(result) if column in line]
    assert len(lines) == 1, result.stderr
    assert f"data: {path}: column {column} (trial means)" in lines[0] and needle in lines[0]


def test_radians_written_under_theta_deg_are_warned_about(tmp_path, cli):
    """A lab's own table with radians in its theta_deg column was read as phases of 0.5-0.8
    deg without a word (eq. 15's slope moved from 0.1235 to 0.1053 and still 'covered' the
    prediction). Phases all within +-2 pi 'deg' are warned about; the same phases in
    degrees are not, nor in a theta_rad column."""
    from bounce_cli.data.plausibility import phase_unit_warning
    from test_data_parameters import lab_table

    path = lab_table(tmp_path)
    frame = pd.read_csv(path)
    assert "theta_deg" in frame.columns
    degrees = frame.drop(columns=[c for c in ("theta_rad",) if c in frame.columns])
    radians = degrees.assign(theta_deg=frame["theta_rad"] if "theta_rad" in frame.columns
                             else degrees["theta_deg"] * 3.141592653589793 / 180)
    for table, warned in ((degrees, False), (radians, True)):
        table.to_csv(path, index=False)
        result = cli("learning", "--data", path, "--out", tmp_path / "o", "--quiet", "--force")
        lines = [line for line in warnings_of(result) if "theta_deg" in line]
        assert len(lines) == int(warned), result.stderr
        if warned:
            assert "radians written as degrees?" in lines[0] and "theta_rad" in lines[0]
    assert phase_unit_warning([0.5, 0.6] * 4, "x") is None  # too few to tell
    assert phase_unit_warning([30.0, 0.5] * 10, "x") is None
    # a stable racket hit at about 3 deg (AC -0.06 g; a review was warned of radians there):
    # the table's AC fits the phases read as degrees, so no warning; phases of 0.5-0.7 whose
    # AC fits them read as radians are warned of
    import numpy as np

    deg = np.linspace(2.5, 3.9, 20)
    amplitude, period, g = 0.2206, 0.92, 9.81
    scale = amplitude * (2 * np.pi / period) ** 2 / g
    ac_deg = -scale * np.sin(np.radians(deg))
    assert phase_unit_warning(deg, "x", (ac_deg, amplitude, period, g)) is None
    rad = np.linspace(0.5, 0.7, 20)
    ac_rad = -scale * np.sin(rad)
    assert phase_unit_warning(rad, "x", (ac_rad, amplitude, period, g)) is not None
