"""claims.py and paper.py: the paper's printed numbers with the tolerance their rounding
allows, and claims that read the results they verify (a changed result changes the verdict)."""

import math
import shutil
from pathlib import Path

import pandas as pd
import pytest

from bounce_cli.paper import values as paper
from bounce_cli.reproduction.claims import CLAIMS, verify

RESULTS = Path(__file__).resolve().parents[1] / "results"


@pytest.mark.parametrize("text, value, tolerance", [
    ("4.5", 4.5, 0.05), ("42", 42.0, 0.5), ("0.068", 0.068, 0.0005), ("-1.11", -1.11, 0.005),
    ("8.4", 8.4, 0.05), ("0.90", 0.9, 0.005),
])
def test_printed_tolerance_is_half_the_last_printed_digit(text, value, tolerance):
    printed = paper.Printed(text, "u", "here")
    assert printed.value == value
    assert printed.tolerance == pytest.approx(tolerance, rel=1e-12)


def test_about_widens_the_tolerance():
    assert paper.ALPHA_P_THRESHOLD.tolerance == 0.025
    assert "about" in paper.ALPHA_P_THRESHOLD.tolerance_text()


def test_at_parameters_tells_the_papers_sets_apart():
    assert paper.at_parameters(paper.FIG3_MODEL, paper.FIG3_MODEL)
    assert not paper.at_parameters(paper.FIG8_MODEL, paper.FIG3_MODEL)
    assert not paper.at_parameters(paper.FIG3_MODEL.with_alpha(0.6), paper.FIG3_MODEL)


def test_every_claim_states_its_paper_value_and_tolerance():
    for claim in CLAIMS:
        assert claim.paper and claim.tolerance, claim.key
        if claim.printed is not None:
            assert claim.paper.startswith(claim.printed.text)
            assert math.isfinite(claim.printed.tolerance) and claim.printed.tolerance > 0


def copy_results(tmp_path):
    copy = tmp_path / "results"
    shutil.copytree(RESULTS, copy, ignore=shutil.ignore_patterns("*.png", "basin.csv"))
    shutil.copy(RESULTS / "basin" / "basin.csv", copy / "basin" / "basin.csv")
    return copy


def verdicts(results):
    return {v.claim.key: v for v in verify(results)}


def test_v0_claim_reads_the_recorded_responses(tmp_path):
    """v_0 at alpha_p = 0.7 comes from relaxation.csv, not from the engine: moving the
    recorded v_0 moves our value and the verdict."""
    copy = copy_results(tmp_path)
    assert verdicts(copy)["v0_perturbed"].status == "reproduced"
    path = copy / "impulse" / "relaxation.csv"
    df = pd.read_csv(path)
    df["v0_m_s"] = df["v0_m_s"] + 0.2
    df.to_csv(path, index=False)
    moved = verdicts(copy)["v0_perturbed"]
    assert moved.status == "differs" and "5.916" in moved.ours


def test_threshold_claim_uses_the_printed_value_and_its_about(tmp_path):
    copy = copy_results(tmp_path)
    path = copy / "impulse" / "threshold.csv"
    df = pd.read_csv(path)
    up = df.direction == "increase"
    for value, status in ((0.674, "reproduced"), (0.676, "differs")):  # 0.65 +- 0.025
        df.loc[up, "alpha_p_threshold"] = value
        df.to_csv(path, index=False)
        assert verdicts(copy)["impulse_threshold"].status == status
