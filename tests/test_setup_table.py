"""The set-up table (setup.csv): written and read back, and a damaged file is one line."""

import math

import pytest

from bounce_cli.runtime.config import ConfigError
from bounce_cli.data.setup_table import SetupQuantity, read_setup, setup_frame, setup_path


def test_round_trip_beside_the_impacts_table(tmp_path):
    impacts = tmp_path / "impacts.csv"
    quantities = [SetupQuantity("g_m_s2", 5.81, 0.02, 40, "free flights"),
                  SetupQuantity("alpha", 0.49, math.nan, 120)]
    setup_frame(quantities).to_csv(setup_path(impacts), index=False)
    back = read_setup(impacts)
    assert list(back) == ["g_m_s2", "alpha"]
    assert back["g_m_s2"] == quantities[0]
    assert back["alpha"].estimate == 0.49 and math.isnan(back["alpha"].se)
    assert back["alpha"].n == 120 and back["alpha"].note == ""


def test_no_file_is_an_empty_setup(tmp_path):
    assert read_setup(tmp_path / "impacts.csv") == {}


def test_a_quantity_named_twice_is_refused_when_written_and_read(tmp_path):
    with pytest.raises(ValueError):
        setup_frame([SetupQuantity("g_m_s2", 9.8), SetupQuantity("g_m_s2", 9.7)])
    (tmp_path / "setup.csv").write_text("quantity,estimate\ng_m_s2,9.8\ng_m_s2,9.7\n")
    with pytest.raises(ConfigError, match="line 3: quantity 'g_m_s2' given twice"):
        read_setup(tmp_path / "impacts.csv")


@pytest.mark.parametrize("text, needle", [
    ("quantity,value\ng_m_s2,9.8\n", "missing column(s) estimate"),
    ("quantity,estimate\ng_m_s2,n/a\n", "estimate of 'g_m_s2' is not a finite number"),
    ("quantity,estimate\ng_m_s2,\n", "not a finite number"),
])
def test_a_damaged_setup_table_is_one_error_naming_the_file(tmp_path, text, needle):
    (tmp_path / "setup.csv").write_text(text)
    with pytest.raises(ConfigError) as info:
        read_setup(tmp_path / "impacts.csv")
    assert needle in str(info.value) and "setup.csv" in str(info.value)
