"""bounce study: a simulated study with known truth is recovered unit by unit and as a group;
manifest errors are one line before anything runs; a damaged file is one failure row; the
results do not depend on workers or on an interruption."""

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import bounce_cli
from bounce_cli.runtime.artifacts import read_frames
from bounce_cli.runtime.config import load_config
from bounce_cli.experiments import study
from bounce_cli.experiments.base import RunOptions

#: a small study: fast enough for every run of the suite
#: (40 s trials: each unit has the 200 pairs acf --data needs for an interval of the radius)
SIM = ["--set", "subjects.count=4", "--set", "trials=4", "--set", "duration_s=40",
       "--set", "subjects.ac_slope_sd_g=0.005", "--set", "subjects.ac_slope_mean_g=-0.05"]
#: the trust study of acf --data at a small size (its own tests cover it)
FAST = ["--set", "settings.acf.data_analysis.trust_repetitions=10",
        "--set", "settings.acf.data_analysis.trust_bounces=[100]",
        "--set", "model.alpha=0.5", "--set", "model.g=9.81"]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory, cli_module):
    out = tmp_path_factory.mktemp("sim") / "sim"
    result = cli_module("simulate-study", "--quiet", "--out", out, *SIM)
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def cli_module():
    from typer.testing import CliRunner

    from bounce_cli.cli.commands import app

    runner = CliRunner()
    return lambda *args: runner.invoke(app, [str(a) for a in args])


#: a tiny study for the quick tests: 2 subjects x 1 condition x 3 trials
TINY = ["--set", "subjects.count=2", "--set", "conditions=[{name: a}]", "--set", "trials=3",
        "--set", "duration_s=10"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, cli_module):
    out = tmp_path_factory.mktemp("tiny") / "sim"
    result = cli_module("simulate-study", "--quiet", "--out", out, *TINY)
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def tiny_study(tiny, tmp_path_factory, cli_module):
    out = tmp_path_factory.mktemp("tiny-study") / "study"
    result = cli_module("study", "--manifest", tiny / "study.csv", "--out", out, "--jobs", "2",
                        "--set", "analyses=[regression, learning]", "--figures", "all", *FAST)
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def studied(simulated, tmp_path_factory, cli_module):
    out = tmp_path_factory.mktemp("study") / "study"
    result = cli_module("study", "--manifest", simulated / "study.csv", "--out", out,
                        "--jobs", "1", *FAST)
    assert result.exit_code == 0, result.output
    return out, result


@pytest.mark.slow
def test_every_unit_and_the_group_tables_are_written(studied):
    out, result = studied
    group = pd.read_csv(out / "group.csv")
    assert len(group) == 8 and set(group["condition"]) == {"vision", "no-vision"}
    assert (group["trials"] == 4).all() and (group["failures"] == 0).all()
    for name in ("group_regression.csv", "group_learning.csv", "group_stability.csv",
                 "group_acf.csv", "failures.csv", "report.html", "s1/report.html",
                 "s1/vision/impacts.csv", "s1/vision/acf/stability_data.csv",
                 "s1/vision/learning/trials.csv", "s1/vision/regression/fit.csv",
                 "s1/vision/extract/s1_vision_t1/impacts.csv", "group_learning.png"):
        assert (out / name).is_file(), name
    assert pd.read_csv(out / "failures.csv").empty
    assert "study: 8 unit(s)" in result.stderr


@pytest.mark.slow
def test_each_unit_recovers_its_truth(studied, simulated):
    """Per unit: the mean AC of its trials within 0.02 g of the simulated targets, the racket
    period within 1 ms, and the model's radius is eq. 10's at alpha 0.5 (complex regime)."""
    out, _ = studied
    group = pd.read_csv(out / "group.csv").set_index(["subject", "condition"])
    truth = pd.read_csv(simulated / "truth.csv").groupby(["subject", "condition"]).mean(
        numeric_only=True)  # over the impacts, as the study averages
    for key, row in group.iterrows():
        assert row["ac_mean_g"] == pytest.approx(truth.loc[key, "racket_acc_g"], abs=0.02), key
        assert row["racket_period_mean_s"] == pytest.approx(
            truth.loc[key, "racket_period_s"], abs=1e-3)
        assert row["model_spectral_radius"] == pytest.approx(0.5, abs=1e-9)


@pytest.mark.slow
def test_the_group_recovers_the_learning_trend_and_eq15(studied, simulated):
    """The mixed model's slope interval covers the subjects' mean AC slope (-0.05 g/trial,
    SD 0.005 across subjects, clipped nowhere at these ACs); the pooled Fig. 7 fit covers eq.
    15's prediction and an intercept of 0 in each condition."""
    out, _ = studied
    learning = pd.read_csv(out / "group_learning.csv").set_index(["condition", "quantity"])
    for condition in ("vision", "no-vision"):
        row = learning.loc[(condition, "ac_mean_g")]
        assert row["ci_low"] <= -0.05 <= row["ci_high"], row.to_dict()
        assert row["subjects"] == 4
    # the interval is t on the containment df, written as a whole number
    assert learning["df"].dtype.kind == "i"
    assert set(learning.loc[learning.method.str.contains("slope"), "df"]) <= {3}
    regression = pd.read_csv(out / "group_regression.csv")
    assert len(regression) == 2
    assert regression["intercept_ci_covers_zero"].all()
    assert regression["slope_ci_covers_prediction"].all()
    assert (regression["r2"] > 0.95).all()


@pytest.mark.slow
def test_the_data_are_as_fast_as_the_model_that_made_them(studied):
    """The recordings were made by the model: the paired difference of the spectral radii
    (data - model) has an interval covering 0 in each condition (the paper's "too slow"
    finding is a difference whose interval excludes 0)."""
    out, _ = studied
    table = pd.read_csv(out / "group_stability.csv")
    ols = table[table["estimate"] == "ols"]
    assert len(ols) == 2
    assert (ols["units"] == 4).all(), ols
    assert ((ols["ci_low"] <= 0) & (ols["ci_high"] >= 0)).all(), ols


@pytest.mark.slow
def test_the_report_is_self_contained(tiny_study):
    out = tiny_study
    text = (out / "report.html").read_text()
    assert text.startswith("<!DOCTYPE html>")
    assert "data:image/png;base64," in text
    assert "http://" not in text and "https://" not in text and "<script" not in text
    for subject in ("s1", "s2"):
        assert f"Subject {subject}" in text
    own = (out / "s2" / "report.html").read_text()
    assert "Subject s2" in own and "Subject s1" not in own
    # every figure the report shows is a file too, and each unit's figures are there
    assert (out / "group_regression.png").is_file()
    assert (out / "s1" / "a" / "regression" / "regression.png").is_file()
    assert pd.read_csv(out / "group.csv").shape[0] == 2


@pytest.mark.slow
def test_run_json_names_the_manifest_and_every_file_with_its_sha256(tiny, tiny_study):
    """Provenance: which recordings, with which bytes, the results were made from (run.json
    had the manifest's path among the overrides and nothing of the files)."""
    import hashlib
    import json

    def sha256(path):
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()

    inputs = json.loads((tiny_study / "run.json").read_text())["inputs"]
    manifest = (tiny / "study.csv").resolve()
    assert inputs["manifest"] == {"path": str(manifest), "sha256": sha256(manifest)}
    rows = pd.read_csv(manifest)
    listed = [tiny / name for column in ("file", "events") if column in rows
              for name in rows[column].dropna()]
    assert len(listed) == 6  # three trials of two subjects, no events: the tiny study
    assert sorted(f["path"] for f in inputs["files"]) == sorted(str(p.resolve())
                                                              for p in listed)
    assert all(f["sha256"] == sha256(f["path"]) for f in inputs["files"])


@pytest.mark.slow
def test_figure_format_and_dpi_reach_the_study_s_figures(tiny, tmp_path, cli_module):
    """--figure-format pdf --dpi 100 were accepted and ignored (PNGs at 150 dpi, no PDF).
    Now each figure is written in the formats asked for and as the PNG the report embeds,
    at the resolution asked for."""
    from PIL import Image

    out = tmp_path / "study"
    result = cli_module("study", "--manifest", tiny / "study.csv", "--out", out, "--jobs", "1",
                        "--set", "analyses=[regression, learning]", "--figures", "all",
                        "--figure-format", "pdf", "--dpi", "100", *FAST)
    assert result.exit_code == 0, result.output
    pngs = sorted(p.relative_to(out).with_suffix("") for p in out.rglob("*.png"))
    pdfs = sorted(p.relative_to(out).with_suffix("") for p in out.rglob("*.pdf"))
    assert pngs == pdfs and len(pngs) > 4  # the group's and every unit's
    assert (out / "group_regression.pdf").read_bytes().startswith(b"%PDF")
    assert Image.open(out / "group_regression.png").info["dpi"][0] == pytest.approx(100, abs=0.1)


@pytest.mark.slow
def test_a_recording_s_extraction_warning_reaches_the_study_and_its_report(tiny, tmp_path,
                                                                           cli_module):
    """A ball dropout written as 0 in one recording: bounce extract warns of it, but the
    study said nothing (a review found it). Now the warning names the unit, the recording and
    the key as the study takes it, on stderr and in the report."""
    sim = tmp_path / "sim"
    shutil.copytree(tiny, sim)
    target = sim / "recordings" / "s2_a_t2.csv"
    frame = pd.read_csv(target)
    frame.loc[frame["t_s"].between(2.0, 2.05), "ball_x_m"] = 0.0
    frame.to_csv(target, index=False)
    out = tmp_path / "study"
    result = cli_module("study", "--manifest", sim / "study.csv", "--out", out, "--jobs", "1",
                        "--set", "analyses=[regression]", *FAST)
    assert result.exit_code == 0, result.output
    said = [line for line in result.output.splitlines() if "exactly 0" in line]
    assert len(said) == 1 and "s2_a_t2: extract:" in said[0], result.output
    assert "--set 'extract.csv.missing_heights=[0]'" in said[0]
    assert "exactly 0" in (out / "report.html").read_text()


@pytest.mark.slow
def test_pages_are_per_value_of_the_first_grouping_factor_named_by_it(tiny, tmp_path,
                                                                       cli_module):
    """With grouping [condition, subject] the pages are per condition: they were titled
    "Subject a", and a recording without a condition made its page's path "/report.html" (a
    path outside the run directory: the study stopped)."""
    sim = tmp_path / "sim"
    shutil.copytree(tiny, sim)
    manifest = pd.read_csv(sim / "study.csv", dtype=str, keep_default_na=False)
    manifest.loc[manifest["subject"] == "s2", "condition"] = ""
    manifest.to_csv(sim / "study.csv", index=False)
    out = tmp_path / "study"
    result = cli_module("study", "--manifest", sim / "study.csv", "--out", out, "--jobs", "1",
                        "--set", "analyses=[regression]", "--set",
                        "grouping=[condition, subject]", *FAST)
    assert result.exit_code == 0, result.output
    assert "Condition a" in (out / "a" / "report.html").read_text()
    assert "Condition -" in (out / "-" / "report.html").read_text()
    assert "Subject a" not in (out / "report.html").read_text()


@pytest.mark.slow
def test_a_damaged_file_is_one_failure_row_and_exit_1(tmp_path, cli_module):
    """One unreadable recording: one failures.csv row, every other file and unit analysed,
    exit 1 after writing."""
    sim = tmp_path / "sim"
    assert cli_module("simulate-study", "--quiet", "--out", sim, "--set", "subjects.count=2",
                      "--set", "conditions=[{name: a}]", "--set", "trials=4",
                      "--set", "duration_s=10", "--set", "damaged_files=1").exit_code == 0
    out = tmp_path / "study"
    result = cli_module("study", "--manifest", sim / "study.csv", "--out", out,
                        "--set", "analyses=[regression]", "--set", "report.unit_figures=false",
                        *FAST)
    assert result.exit_code == 1, result.output
    failures = pd.read_csv(out / "failures.csv")
    assert len(failures) == 1
    assert failures.iloc[0]["stage"] == "extract"
    assert failures.iloc[0]["file"].endswith("s2_a_t4.csv")
    assert "1 failure(s)" in result.stderr
    group = pd.read_csv(out / "group.csv").set_index("subject")
    assert group.loc["s1", "trials"] == 4 and group.loc["s2", "trials"] == 3
    assert (out / "s2" / "a" / "regression" / "fit.csv").is_file()


def test_one_short_recording_is_left_out_of_the_analyses_that_need_more(tmp_path, cli_module):
    """A trial cut to 2 s (a few impacts) costs that trial, with a warning naming the setting,
    not the unit's learning trend (the review's lab file failed the whole unit); the trials
    after it keep their numbers in the series."""
    sim = tmp_path / "sim"
    assert cli_module("simulate-study", "--quiet", "--out", sim, "--set", "subjects.count=1",
                      "--set", "conditions=[{name: a}]", "--set", "trials=4",
                      "--set", "duration_s=10").exit_code == 0
    manifest_frame = pd.read_csv(sim / "study.csv")
    recording = pd.read_csv(sim / manifest_frame.loc[0, "file"])
    cut = tmp_path / "short.csv"
    recording[recording["t_s"] < recording["t_s"].min() + 2.0].to_csv(cut, index=False)
    manifest_frame["file"] = [str(cut)] + [str(sim / f) for f in manifest_frame["file"][1:]]
    manifest_frame.to_csv(tmp_path / "study.csv", index=False)
    out = tmp_path / "out"
    result = cli_module("study", "--manifest", tmp_path / "study.csv", "--out", out,
                        "--set", "analyses=[learning]", "--figures", "none", *FAST)
    assert result.exit_code == 0, result.output
    said = " ".join(result.stderr.split())
    assert "learning: trial 1:" in said and "left out (lower min_bounces to keep it)" in said
    trials = pd.read_csv(out / "s1" / "a" / "learning" / "trials.csv")
    assert trials["trial_number"].tolist() == [2, 3, 4]
    assert pd.read_csv(out / "failures.csv").empty


def test_a_unit_too_small_for_its_own_fig7_still_counts_in_the_pooled_one(tiny, tmp_path,
                                                                        cli_module):
    """A subject with 2 trials: its own Fig. 7 fit needs 3 and is not run (a warning); its
    trial means still enter the fit pooled over the study (they were left out: the pooled fit
    had 3 trials of 5)."""
    manifest_frame = pd.read_csv(tiny / "study.csv")
    last = manifest_frame[manifest_frame.subject.astype(str) == "s2"].index[-1]
    manifest_frame = manifest_frame.drop(index=last)
    manifest_frame["file"] = [str(tiny / f) for f in manifest_frame["file"]]
    manifest_frame.to_csv(tmp_path / "study.csv", index=False)
    out = tmp_path / "out"
    result = cli_module("study", "--manifest", tmp_path / "study.csv", "--out", out,
                        "--set", "analyses=[regression]", "--figures", "none", *FAST)
    assert result.exit_code == 0, result.output
    assert "regression: not run" in " ".join(result.stderr.split())
    own = pd.read_csv(out / "s2" / "a" / "regression" / "trials.csv")
    assert len(own) == 2 and {"a_r_m", "tau_s", "tau2_s2", "theta_deg"} <= set(own.columns)
    pooled = pd.read_csv(out / "group_regression.csv")
    assert pooled["n"].tolist() == [5] and pooled["subjects"].tolist() == [2]


def test_two_recordings_with_one_stem_in_a_unit_keep_their_own_outputs(tiny, tmp_path,
                                                                        cli_module):
    """``A/t.csv`` and ``B/t.csv`` of one subject and condition (issue 36: one's files were
    overwritten by the other's, and their impacts pooled as one trial)."""
    for folder, trial in (("A", 1), ("B", 2)):
        (tmp_path / folder).mkdir()
        shutil.copy(tiny / "recordings" / f"s1_a_t{trial}.csv", tmp_path / folder / "t.csv")
    (tmp_path / "study.csv").write_text("file,subject,condition\nA/t.csv,s1,a\nB/t.csv,s1,a\n")
    out = tmp_path / "out"
    cli_module("study", "--manifest", tmp_path / "study.csv", "--out", out, "--quiet",
               "--set", "analyses=[regression]", "--set", "report.unit_figures=false", *FAST)
    extracted = out / "s1" / "a" / "extract"
    assert sorted(p.name for p in extracted.iterdir()) == ["t-line2", "t-line3"]
    first, second = (pd.read_csv(extracted / name / "impacts.csv")
                     for name in ("t-line2", "t-line3"))
    assert not first["t_s"].equals(second["t_s"])
    pooled = pd.read_csv(out / "s1" / "a" / "impacts.csv")
    assert len(pooled) == len(first) + len(second)
    assert sorted(set(pooled["trial"])) == ["t-line2:1", "t-line3:1"]


def test_recording_names_are_the_stems_unless_two_share_one(tmp_path):
    from bounce_cli.data.study_manifest import ManifestRow, Unit

    rows = tuple(ManifestRow(line, tmp_path / path, None, {"subject": "s1"})
                 for line, path in ((2, "A/t.csv"), (3, "u.csv"), (4, "B/t.csv"),
                                    (5, "t-line4.csv")))
    names = study.recording_names(Unit(("s1",), ("subject",), rows))
    assert names == ["t-line2", "u", "t-line4-", "t-line4"]
    rows = tuple(ManifestRow(line, tmp_path / path, None, {"subject": "s1"})
                 for line, path in ((2, "T.csv"), (3, "t.csv"), (4, "u.csv")))
    assert study.recording_names(Unit(("s1",), ("subject",), rows)) == ["T-line2", "t-line3",
                                                                        "u"]


def manifest(tmp_path, text, files=("a.csv",)):
    for name in files:
        (tmp_path / name).write_text("trial,t_s,racket_x_m,ball_x_m\n")
    path = tmp_path / "study.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, needle", [
    ("file,condition\na.csv,x\n", "missing column(s) subject"),
    ("file,subject\nb.csv,s1\n", "line 2: file 'b.csv': no such file"),
    ("file,subject\na.csv,s1\na.csv,s1\n", "line 3: file 'a.csv': the same recording as line 2"),
    # one file under two trials (or two subjects) is one recording pooled twice
    ("file,subject,trial\na.csv,s1,1\na.csv,s1,2\n", "line 3: file 'a.csv': the same recording"),
    ("file,subject\na.csv,s1\na.csv,s2\n", "the same recording as line 2"),
    ("file,subject\na.csv,s/1\n", "line 2: subject 's/1': a factor value names a folder"),
    ("file,subject\n", "no rows"),
    ("file,subject,extract.units.length\na.csv,s1,[mm\n", "cannot parse"),
    # pandas renames the second subject to subject.1 (issue 36: it passed)
    ("file,subject,subject\na.csv,s1,s2\n", "column(s) subject given twice"),
    ("file,subject, condition,condition\na.csv,s1,x,y\n", "column(s) condition given twice"),
])
def test_manifest_errors_are_one_line_before_anything_runs(tmp_path, cli, user_error, text,
                                                           needle):
    out = tmp_path / "out"
    result = cli("study", "--manifest", manifest(tmp_path, text), "--out", out,
                 "--set", "model.alpha=0.5", "--set", "model.g=9.81")
    user_error(result, "manifest", needle)
    assert not out.exists()


@pytest.mark.parametrize("target", ["/etc/passwd", "/etc/hostname", "/proc/self/status"])
@pytest.mark.parametrize("linked", [False, True])
def test_a_system_file_in_the_manifest_is_refused_without_its_content(tmp_path, cli, user_error,
                                                                      target, linked):
    """Issue 36: /etc/passwd's first line reached failures.csv and report.html (as the
    columns "the file has"). Refused before anything runs, by its name, never its bytes."""
    if not Path(target).is_file():
        pytest.skip(f"no {target} here")
    cell = target
    if linked:
        (tmp_path / "t.csv").symlink_to(target)
        cell = "t.csv"
    path = tmp_path / "study.csv"
    path.write_text(f"file,subject,condition\n{cell},s1,a\n")
    out = tmp_path / "out"
    result = cli("study", "--manifest", path, "--out", out, *FAST)
    user_error(result, "line 2", f"file {cell!r}", "a system file, not a recording")
    first = Path(target).read_text().splitlines()[0].strip()
    assert first not in result.output
    assert not out.exists()


def test_a_device_in_the_manifest_is_not_a_recording(tmp_path, cli, user_error):
    path = tmp_path / "study.csv"
    path.write_text("file,subject,condition\na.csv,s1,a\n")
    (tmp_path / "a.csv").mkdir()
    user_error(cli("study", "--manifest", path, "--out", tmp_path / "out", *FAST),
               "line 2", "file 'a.csv'", "not a regular file")


@pytest.mark.parametrize("text, needle", [
    # two recordings of a unit under one trial label: their impacts would merge (the run
    # failed later in every analysis, "impact k = 0 appears twice", naming no file)
    ("file,subject,condition,trial\na.csv,s1,x,1\nb.csv,s1,x,2\nc.csv,s1,x,1\n",
     "lines 2 and 4: subject s1, condition x: trial '1' twice"),
    # one folder on macOS and Windows
    ("file,subject,condition\na.csv,s1,Vision\nb.csv,s1,vision\n",
     "lines 2 and 3: units 's1/Vision' and 's1/vision' differ only in case"),
])
def test_units_that_would_merge_are_one_line_before_anything_runs(tmp_path, cli, user_error,
                                                                  text, needle):
    out = tmp_path / "out"
    result = cli("study", "--manifest", manifest(tmp_path, text, ("a.csv", "b.csv", "c.csv")),
                 "--out", out, "--set", "model.alpha=0.5", "--set", "model.g=9.81")
    user_error(result, "manifest", needle)
    assert not out.exists()


def test_one_file_read_twice_with_other_settings_is_two_recordings(tmp_path):
    """Two balls in one recording (a row each, its own marker) are two recordings."""
    from bounce_cli.data.study_manifest import read_manifest

    path = manifest(tmp_path, "file,subject,extract.markers.ball\na.csv,s1,b1\na.csv,s2,b2\n")
    assert [row.overrides for row in read_manifest(path).rows] == [("markers.ball=b1",),
                                                                  ("markers.ball=b2",)]


def test_trials_that_are_not_numbers_are_named_where_they_are_ordered(tmp_path):
    from bounce_cli.data.study_manifest import read_manifest

    path = manifest(tmp_path, "file,subject,trial\na.csv,s1,practice\nb.csv,s1,2\n"
                              "c.csv,s1,1\nd.csv,s2,\n", ("a.csv", "b.csv", "c.csv", "d.csv"))
    found = read_manifest(path)
    first, second = found.units(("subject",))
    assert [row.factors["trial"] for row in first.rows] == ["1", "2", "practice"]
    assert found.trial_order_notes(first) == [
        "subject s1: trial 'practice' (manifest line 2) is not a number: ordered after the "
        "numbered trials, as trial 3 of 3"]
    assert found.trial_order_notes(second) == []  # no numbered trial: the order as listed


def test_a_grouping_factor_the_manifest_lacks_is_one_line(tmp_path, cli, user_error):
    result = cli("study", "--manifest", manifest(tmp_path, "file,subject\na.csv,s1\n"),
                 "--out", tmp_path / "out")
    user_error(result, "grouping", "'condition'")


def test_an_unknown_setting_fails_before_anything_runs(tmp_path, cli, user_error):
    result = cli("study", "--manifest", manifest(tmp_path, "file,subject\na.csv,s1\n"),
                 "--set", "settings.acf.max_lagg=4", "--out", tmp_path / "out")
    user_error(result, "max_lagg")
    # the message names --set, not the bundled study.yaml the key is not in
    assert result.output.strip().startswith("bounce: error: --set: settings.acf: max_lagg")
    result = cli("study", "--manifest", manifest(tmp_path, "file,subject\na.csv,s1\n"),
                 "--set", "extract.units.lenght=mm", "--out", tmp_path / "out")
    user_error(result, "--set: extract: units.lenght: unknown key (did you mean units.length?)")
    # a misspelt block of the extract settings: the message names the block, not the key
    result = cli("study", "--manifest", manifest(tmp_path, "file,subject\na.csv,s1\n"),
                 "--set", "extract.unitz.length=mm", "--out", tmp_path / "out")
    user_error(result, "--set: extract: unitz: unknown key (did you mean units?)")
    assert "study.yaml" not in result.output


@pytest.mark.slow
def test_without_alpha_and_g_the_data_must_show_them(tiny, tmp_path, cli_module):
    """Recordings without events or a measured set-up and no model.alpha/model.g: each
    unit is a failure naming both ways to give them (nothing silently at a default)."""
    rows = pd.read_csv(tiny / "study.csv").head(3)
    rows["file"] = [str(tiny / f) for f in rows["file"]]
    rows.to_csv(tmp_path / "study.csv", index=False)
    result = cli_module("study", "--manifest", tmp_path / "study.csv", "--out",
                        tmp_path / "out", "--set", "analyses=[regression]")
    failures = pd.read_csv(tmp_path / "out" / "failures.csv")
    if result.exit_code == 0:  # the extraction measures alpha and g from the flights
        group = pd.read_csv(tmp_path / "out" / "group.csv")
        assert group["alpha_source"].str.contains("measured").all()
        return
    assert result.exit_code == 1
    assert failures["stage"].eq("model").all()
    assert "model.alpha" in failures.iloc[0]["error"]


class StopAfter:
    """Checkpoints that keep points in memory and stop the run after ``n`` saves (an
    interrupt in the middle of a study)."""

    def __init__(self, n, stored=None):
        self.n, self.stored = n, dict(stored or {})

    def load(self):
        return dict(self.stored)

    def save(self, index, result):
        self.stored[index] = result
        if len(self.stored) >= self.n:
            raise KeyboardInterrupt


def study_config(simulated, *overrides):
    from bounce_cli.runtime.config import bundled_config_path

    return load_config(study.StudyConfig, bundled_config_path("study"),
                       [f"manifest={simulated / 'study.csv'}", "model.alpha=0.5",
                        "model.g=9.81", "analyses=[regression, learning]",
                        "grouping=[subject]", "report.unit_figures=false", *overrides])


@pytest.mark.slow
def test_an_interrupted_study_resumed_gives_the_same_tables(tiny):
    config = study_config(tiny)
    whole = study.run(config, RunOptions())
    checkpoints = StopAfter(1)
    with pytest.raises(KeyboardInterrupt):
        study.run(config, RunOptions(checkpoints=checkpoints))
    resumed = study.run(config, RunOptions(checkpoints=StopAfter(99, checkpoints.stored)))
    assert "1 resumed" in resumed.summary[0]
    assert whole.frames.keys() == resumed.frames.keys()
    for name, frame in whole.frames.items():
        pd.testing.assert_frame_equal(frame, resumed.frames[name], check_exact=True, obj=name)


@pytest.mark.slow
def test_a_changed_recording_reruns_only_its_unit(tiny, tmp_path):
    copy = tmp_path / "sim"
    shutil.copytree(tiny, copy)
    config = study_config(copy)
    first = StopAfter(99)
    study.run(config, RunOptions(checkpoints=first))
    keys = {i: r["key"] for i, r in first.stored.items()}
    target = copy / "recordings" / "s1_a_t1.csv"
    frame = pd.read_csv(target)
    frame["racket_x_m"] += 0.001  # the lab re-exported this file
    frame.to_csv(target, index=False)
    again = StopAfter(99, first.stored)
    result = study.run(config, RunOptions(checkpoints=again))
    assert "1 resumed" in result.summary[0]
    assert again.stored[0]["key"] != keys[0] and again.stored[1]["key"] == keys[1]


@pytest.mark.slow
def test_two_workers_and_a_dask_cluster_give_identical_group_tables(simulated, tmp_path,
                                                                      cli_module):
    """The same files (group tables and every unit's) on 1 and 2 local workers and on a Dask
    LocalCluster."""
    distributed = pytest.importorskip("distributed")
    args = ["study", "--manifest", simulated / "study.csv", "--quiet", *FAST,
            "--set", "analyses=[learning, regression]"]
    assert cli_module(*args, "--out", tmp_path / "one", "--jobs", "1").exit_code == 0
    assert cli_module(*args, "--out", tmp_path / "two", "--jobs", "2").exit_code == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        result = cli_module(*args, "--out", tmp_path / "dask", "--scheduler",
                            cluster.scheduler_address)
        assert result.exit_code == 0, result.output
    one = read_frames(tmp_path / "one")
    assert "group.csv" in one
    names = sorted(p.relative_to(tmp_path / "one") for p in (tmp_path / "one").rglob("*.csv"))
    assert len(names) > 20
    for other in ("two", "dask"):
        for name in names:
            assert (tmp_path / "one" / name).read_bytes() == (tmp_path / other / name).read_bytes()


@pytest.mark.slow
def test_the_report_renders_in_a_browser(tiny_study, tmp_path):
    """A headless Chromium screenshot of report.html: the page loads from the file system
    and is not blank."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("Chromium is not installed (Debian package chromium)")
    out = tiny_study
    shot = tmp_path / "report.png"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                    "--disable-background-networking", "--no-first-run",
                    f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
                    "--window-size=1200,2400", (out / "report.html").as_uri()],
                   check=True, capture_output=True, timeout=120)
    from matplotlib.image import imread

    pixels = imread(shot)
    assert pixels.shape[0] >= 2000
    assert np.std(pixels[..., :3]) > 0.05  # figures and tables, not an empty page
    assert math.isfinite(float(pixels.mean()))
    assert Path(shot).stat().st_size > 10_000


@pytest.mark.slow
@pytest.mark.parametrize("width", [800, 1280])
def test_no_table_of_the_report_runs_off_the_page(tiny_study, tmp_path, width):
    """Issue 36: the study's report at 800 and 1280 px: every table scrolls in its own box,
    the page has no sideways scroll, the figures fit with their titles."""
    from test_report_layout import CHROMIUM, assert_nothing_runs_off, measure

    if CHROMIUM is None:
        pytest.skip("Chromium is not installed (Debian package chromium)")
    measured = measure(tiny_study / "report.html", width, tmp_path)
    assert len(measured["tables"]) >= 3 and measured["images"]
    assert_nothing_runs_off(measured, width)


@pytest.mark.slow
def test_perturbations_come_with_events_and_give_impulse_responses(tmp_path, cli_module):
    """A perturbed study: events written and named by the manifest, impulse runs per unit,
    group_impulse.csv averages the responses over subjects."""
    sim = tmp_path / "sim"
    assert cli_module("simulate-study", "--quiet", "--out", sim, "--set", "subjects.count=2",
                      "--set", "conditions=[{name: a, velocity_noise_m_s: 0.03}]",
                      "--set", "trials=1", "--set", "duration_s=25",
                      "--set", "perturbations.every=8",
                      "--set", "perturbations.alphas=[0.45, 0.55]").exit_code == 0
    manifest = pd.read_csv(sim / "study.csv")
    assert list(manifest.columns[:2]) == ["file", "events"]
    out = tmp_path / "study"
    result = cli_module("study", "--manifest", sim / "study.csv", "--out", out,
                        "--set", "analyses=[impulse]", "--set", "report.unit_figures=false",
                        "--set", "settings.impulse.data_analysis.min_windows_per_impact=3",
                        "--set", "model.alpha=0.5", "--set", "model.g=9.81")
    assert result.exit_code == 0, result.output
    impulse = pd.read_csv(out / "group_impulse.csv")
    first = impulse[(impulse["quantity"] == "v_m_s") & (impulse["k"] == 0)].set_index("direction")
    assert first.loc["decrease", "mean"] < -0.05 < 0.05 < first.loc["increase", "mean"]
    assert (first["units"] == 2).all()
    assert pd.read_csv(out / "group.csv")["relax_impacts_decrease"].notna().all()


def var1_impacts(seed, n_trials=5, n=35, burn=200):
    """An impacts table of ``n_trials`` trials of ``n`` impacts: eq. 19's VAR(1) at the
    model of a study's unit (alpha 0.5, radius 0.5) about its fixed point, racket cycles
    varying a little. Seed 94 of 5 x 35 gives a jackknifed lag-2 radius of 22 from an
    ill-conditioned fit (issue 36: a simulated study's unit gave 34.7)."""
    from bounce_cli.model.linear import jacobian
    from bounce_cli.model.params import ModelParams

    params = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.094, racket_period=0.564)
    jac, fp = jacobian(params), params.fixed_point()
    chol = np.linalg.cholesky(np.diag([0.05**2, 0.01**2]))
    rng = np.random.default_rng(seed)
    y = np.zeros((n_trials, 2))
    out = np.empty((n_trials, n, 2))
    for k in range(burn + n):
        y = y @ jac.T + rng.standard_normal((n_trials, 2)) @ chol.T
        if k >= burn:
            out[:, k - burn] = y
    racket = np.random.default_rng(seed + 1000)
    return pd.DataFrame({
        "trial": np.repeat(np.arange(1, n_trials + 1), n), "k": np.tile(np.arange(n), n_trials),
        "theta_rad": fp.theta_rad + out[..., 1].ravel(), "v_m_s": fp.v_m_s + out[..., 0].ravel(),
        "racket_period_s": 0.564 + 4e-4 * racket.standard_normal(n_trials * n),
        "racket_amplitude_m": 0.094 + 1e-4 * racket.standard_normal(n_trials * n)})


@pytest.mark.slow
def test_a_wild_lag2_estimate_is_nan_with_its_reason_in_every_table_and_the_report(
        tmp_path, cli_module):
    """Issue 36: a unit's lag-2 radius of 34.74 reached group.csv and report.html, said only
    on stderr. Now NaN in every table with the reason in a note, counted and listed in the
    report's warnings, left out of the group statistics; the other unit's estimates stay."""
    for subject, seed in (("s1", 94), ("s2", 3)):
        var1_impacts(seed).to_csv(tmp_path / f"{subject}_impacts.csv", index=False)
    (tmp_path / "study.csv").write_text("file,subject,condition\ns1_impacts.csv,s1,a\n"
                                        "s2_impacts.csv,s2,a\n")
    out = tmp_path / "out"
    result = cli_module("study", "--manifest", tmp_path / "study.csv", "--out", out,
                        "--set", "analyses=[acf]", "--set", "report.unit_figures=false",
                        "--set", "settings.acf.data_analysis.model_sessions=4", *FAST)
    assert result.exit_code == 0, result.output
    group = pd.read_csv(out / "group.csv", keep_default_na=False, na_values=[""]).set_index(
        "subject")
    assert math.isnan(group.loc["s1", "radius_lag2"])
    assert math.isnan(group.loc["s1", "radius_lag2_ci_low"])
    note = group.loc["s1", "radius_lag2_note"]
    assert note.startswith("spectral radius withheld: ") and "ill-conditioned" in note
    # s2's estimate stands (its note, if any, says why it has no interval: not withheld)
    assert 0.0 < group.loc["s2", "radius_lag2"] < 1.5
    s2_note = group.loc["s2", "radius_lag2_note"]
    assert pd.isna(s2_note) or s2_note.startswith("no interval")
    assert 0.0 < group.loc["s1", "radius_ols"] < 1.5  # OLS of the same data is an estimate
    stab = pd.read_csv(out / "s1" / "a" / "acf" / "stability_data.csv")
    row = stab[(stab["quantity"] == "spectral_radius") & (stab["source"] == "lag2")].iloc[0]
    assert math.isnan(row["estimate"]) and row["note"] == note
    stability = pd.read_csv(out / "group_stability.csv").set_index("estimate")
    assert stability.loc["lag2", "units_withheld"] == 1
    assert stability.loc["ols", "units_withheld"] == 0
    # no table holds a radius above 1.5 (or a non-finite one) without its note
    for path in out.rglob("*.csv"):
        table = pd.read_csv(path)
        columns = [c for c in table.columns if str(c).startswith("radius_")
                   and not str(c).endswith("_note")]
        if "quantity" in table.columns:
            columns.append("estimate")
            table = table[table["quantity"] == "spectral_radius"]
        for column in columns:
            values = pd.to_numeric(table[column], errors="coerce")
            assert not (values > 1.5).any(), (path, column)
    # the report counts and lists the warning; stderr has it, and not the wild estimate
    report = (out / "report.html").read_text()
    warned = [line for line in result.stderr.splitlines() if "spectral radius withheld" in line]
    assert warned and all("bounce: warning: " in line for line in warned)
    assert f"{len(warned)} warning(s)" in report
    assert "<h2>Warnings</h2>" in report and "spectral radius withheld" in report
    assert "22.39" not in result.stderr and "without," not in result.stderr


def test_a_radius_that_is_no_estimate_never_enters_a_group_statistic():
    """A wild value with an interval (a row of an older run, resumed) or a withheld one is
    left out of the paired difference and counted as withheld."""
    from bounce_cli.data.study_manifest import Unit

    group = pd.DataFrame({
        "subject": ["s1", "s2", "s3", "s4"], "condition": "a",
        "model_spectral_radius": [0.5, 0.5, 0.5, 0.5],
        "radius_ols": [0.40, 0.42, 3.0, np.nan], "radius_ols_ci_low": [0.3, 0.32, 2.5, np.nan],
        "radius_ols_ci_high": [0.5, 0.52, 3.5, np.nan],
        "radius_ols_note": ["", "", "", "spectral radius withheld: the estimate is not finite"],
        "radius_lag2": [0.4, 0.45, np.inf, 0.5], "radius_lag2_ci_low": [0.2, 0.3, 0.1, 0.3],
        "radius_lag2_ci_high": [0.6, 0.6, np.inf, 0.7], "radius_lag2_note": ""})
    units = [Unit((s, "a"), ("subject", "condition")) for s in group["subject"]]
    table = study.group_tables({"group.csv": group}, units, study_config(Path("unused")))[
        "group_stability.csv"].set_index("estimate")
    assert table.loc["ols", "units"] == 2 and table.loc["ols", "units_withheld"] == 2
    assert table.loc["ols", "data_mean"] == pytest.approx(0.41)
    assert table.loc["lag2", "units"] == 3 and table.loc["lag2", "units_withheld"] == 1
    assert table.loc["ols", "units_without_interval"] == 0


def test_an_estimate_without_an_interval_says_why_in_group_csv():
    why = ("no interval: 150 triples, fewer than the 1200 the lag2 interval needs without a "
           "check; the trust study at this size: ... (below 90%)")
    entries = study.radius_entries("lag2", 0.518, math.nan, math.nan, why)
    assert entries["radius_lag2"] == 0.518 and entries["radius_lag2_note"] == why
    with_interval = study.radius_entries("ols", 0.46, 0.32, 0.66, "delta method, log scale")
    assert with_interval["radius_ols_note"] == ""  # the interval is there: nothing missing


def test_estimates_without_an_interval_are_left_out_of_the_paired_difference():
    """A unit whose data were too few for an interval (its estimate can be anything) does not
    enter the test of data against model."""
    from bounce_cli.data.study_manifest import Unit

    group = pd.DataFrame({
        "subject": ["s1", "s2", "s3"], "condition": "a",
        "model_spectral_radius": [0.5, 0.5, 0.5],
        "radius_ols": [0.40, 0.42, 0.9], "radius_ols_ci_low": [0.3, 0.32, np.nan],
        "radius_ols_ci_high": [0.5, 0.52, np.nan],
        "radius_lag2": [0.4, np.nan, 0.9], "radius_lag2_ci_low": [0.2, np.nan, np.nan],
        "radius_lag2_ci_high": [0.6, np.nan, np.nan]})
    units = [Unit((s, "a"), ("subject", "condition")) for s in group["subject"]]
    config = study_config(Path("unused"))
    table = study.group_tables({"group.csv": group}, units, config)["group_stability.csv"]
    ols = table.set_index("estimate").loc["ols"]
    assert ols["units"] == 2 and ols["units_without_interval"] == 1
    assert ols["difference_mean"] == pytest.approx(-0.09)
    assert table.set_index("estimate").loc["lag2", "verdict"] == "too few units with an interval"


def test_a_unit_without_an_estimate_is_not_counted_as_one_without_an_interval():
    """A unit whose extraction failed (or whose acf did not run) has no estimate at all: it
    is counted apart (``units_without_estimate``), not as too few data for an interval (a
    reviewer's study: a unit with swapped columns read "1 without an interval")."""
    from bounce_cli.data.study_manifest import Unit

    group = pd.DataFrame({
        "subject": ["s1", "s2", "s3", "s4"], "condition": "a",
        "model_spectral_radius": [0.5, 0.5, 0.5, np.nan], "failures": [0, 0, 0, 1],
        "radius_ols": [0.40, 0.42, 0.9, np.nan], "radius_ols_ci_low": [0.3, 0.32, np.nan, np.nan],
        "radius_ols_ci_high": [0.5, 0.52, np.nan, np.nan]})
    units = [Unit((s, "a"), ("subject", "condition")) for s in group["subject"]]
    table = study.group_tables({"group.csv": group}, units, study_config(Path("unused")))[
        "group_stability.csv"].set_index("estimate")
    ols = table.loc["ols"]
    assert ols["units"] == 2 and ols["units_without_interval"] == 1
    assert ols["units_without_estimate"] == 1 and ols["units_withheld"] == 0
    line = study._stability_line(ols.to_dict() | {"estimate": "ols"})
    assert "1 without an interval" in line and "1 without an estimate" in line


def test_each_recording_gets_its_own_folder_inside_the_unit():
    """A stem that is '..' (a file named ``...csv``) or '.' would put a recording's outputs
    outside ``<unit>/extract/`` (onto the unit's own impacts.csv); two recordings ``A/t.csv``,
    ``B/t.csv`` would share one folder and one trial label."""
    from bounce_cli.data.study_manifest import ManifestRow, Unit

    rows = [ManifestRow(line, Path(f"/x/{name}"), None, {"subject": "s1"})
            for line, name in ((2, "A/t.csv"), (3, "B/t.csv"), (4, "...csv"), (5, "..csv"),
                               (6, "u.c3d"))]
    names = study.recording_names(Unit(("s1",), ("subject",), rows))
    assert names == ["t-line2", "t-line3", "file-line4", "file-line5", "u"]
    assert [study.row_label(r, n) for r, n in zip(rows, names)][:2] == ["t-line2", "t-line3"]


@pytest.mark.slow
def test_recordings_named_dot_dot_or_alike_keep_their_own_outputs(tmp_path, cli_module):
    """End to end: ``...csv`` was a traceback after the whole extraction ("not a path inside
    the run directory"), and ``A/t.csv`` with ``B/t.csv`` left one's files and merged their
    trials."""
    sim = tmp_path / "sim"
    assert cli_module("simulate-study", "--quiet", "--out", sim, "--set", "subjects.count=1",
                      "--set", "conditions=[{name: a}]", "--set", "trials=3",
                      "--set", "duration_s=10").exit_code == 0
    for folder, name, trial in (("A", "t.csv", 1), ("B", "t.csv", 2), (".", "...csv", 3)):
        (sim / folder).mkdir(exist_ok=True)
        shutil.copy(sim / "recordings" / f"s1_a_t{trial}.csv", sim / folder / name)
    (sim / "m.csv").write_text("file,subject,condition\nA/t.csv,s1,a\nB/t.csv,s1,a\n"
                               "...csv,s1,a\n")
    out = tmp_path / "study"
    result = cli_module("study", "--manifest", sim / "m.csv", "--out", out, "--set",
                        "analyses=[regression]", "--set", "report.unit_figures=false", *FAST)
    assert result.exit_code == 0, result.output
    unit = out / "s1" / "a"
    assert sorted(p.name for p in (unit / "extract").iterdir()) == [
        "file-line4", "t-line2", "t-line3"]
    pooled = pd.read_csv(unit / "impacts.csv")
    assert pooled["trial"].nunique() == 3
    per_file = sum(len(pd.read_csv(p)) for p in (unit / "extract").glob("*/impacts.csv"))
    assert per_file == len(pooled)


@pytest.mark.slow
def test_a_labs_small_study_gets_an_interval_for_every_radius(tmp_path, cli_module):
    """Issue 36's case: 3 subjects x 2 conditions x 3 trials x 20 s (about 90 impacts per
    unit, below the fixed minimum of 200 pairs). The trust study at each unit's own size
    trusts the OLS interval (the extraction's measurement noise is small), so every unit's
    OLS and VARX-OLS radius has an interval, and group_stability.csv has the data-vs-model
    paired difference with its interval per condition."""
    sim = tmp_path / "sim"
    assert cli_module("simulate-study", "--quiet", "--out", sim, "--set", "subjects.count=3",
                      "--set", "trials=3", "--set", "duration_s=20",
                      "--set", "racket.period_sd_s=0.005").exit_code == 0
    out = tmp_path / "study"
    result = cli_module("study", "--manifest", sim / "study.csv", "--out", out, "--jobs", "2",
                        "--set", "analyses=[acf]",
                        "--set", "settings.acf.data_analysis.trust_repetitions=100",
                        "--set", "settings.acf.data_analysis.trust_bounces=[100]")
    assert result.exit_code == 0, result.output
    group = pd.read_csv(out / "group.csv")
    assert len(group) == 6 and (group["impacts"] < 200).all()
    for method in ("ols", "varx_ols"):
        low, high = group[f"radius_{method}_ci_low"], group[f"radius_{method}_ci_high"]
        assert np.isfinite(low).all() and np.isfinite(high).all(), group[
            [f"radius_{method}", f"radius_{method}_note"]]
        assert ((low < group[f"radius_{method}"]) & (group[f"radius_{method}"] < high)).all()
    stab = pd.read_csv(out / "s1" / "vision" / "acf" / "stability_data.csv")
    note = stab[(stab.quantity == "spectral_radius") & (stab.source == "ols+jackknife")]
    assert "measured by the trust study" in note["note"].iloc[0]
    paired = pd.read_csv(out / "group_stability.csv")
    ols = paired[paired["estimate"] == "ols"]
    assert len(ols) == 2 and (ols["units"] == 3).all()
    assert np.isfinite(ols["ci_low"]).all() and (ols["ci_low"] < ols["ci_high"]).all()
    radii = group.filter(regex=r"^radius_[a-z_0-9]+$")
    for value in radii.drop(columns=radii.filter(like="_note").columns).to_numpy().ravel():
        assert math.isnan(value) or value <= 1.5


@pytest.mark.parametrize("figures, group_png, unit_png", [("none", False, False),
                                                          ("group", True, False),
                                                          (None, True, False),
                                                          ("unit_figures", True, True)])
def test_figures_option_draws_only_what_is_asked(tiny, tiny_study, tmp_path, cli_module,
                                                 figures, group_png, unit_png):
    """``--figures none|group``: no unit figure (and no group figure with none), the same
    tables as the run that drew them all; by default the group's only, every unit's with
    ``report.unit_figures``."""
    out = tmp_path / str(figures)
    option = {None: [], "unit_figures": ["--set", "report.unit_figures=true"]}.get(
        figures, ["--figures", str(figures)])
    result = cli_module("study", "--manifest", tiny / "study.csv", "--out", out, "--quiet",
                        "--set", "analyses=[regression, learning]", *option, *FAST)
    assert result.exit_code == 0, result.output
    assert (out / "group_regression.png").is_file() == group_png
    assert (out / "s1" / "a" / "regression" / "regression.png").is_file() == unit_png
    report = (out / "report.html").read_text()
    assert ("s1/a/regression/regression.png" in report) == unit_png
    assert ("--figures all" in report) == (not unit_png)  # how to get them, where absent
    assert (tiny_study / "s1" / "a" / "regression" / "regression.png").is_file()
    for name in ("group.csv", "group_regression.csv", "s1/a/regression/fit.csv"):
        pd.testing.assert_frame_equal(pd.read_csv(out / name), pd.read_csv(tiny_study / name))


def test_a_unit_table_passes_through_json_unchanged():
    """A worker's tables reach the parent (and the checkpoints) as JSON: every float exactly
    (NaN, inf, -0.0, the last bit), every dtype as it was."""
    import json

    import numpy as np
    import pandas as pd

    from bounce_cli.experiments.study import frame_from_json, frame_to_json

    frame = pd.DataFrame({
        "x": [0.1 + 0.2, float("nan"), float("inf"), -0.0, 5e-324],
        "n": np.array([1, 2, 3, -4, 2**60], dtype=np.int64),
        "ok": [True, False, True, True, False],
        "label": ["a", None, "c", "d", "e"],
        "kind": pd.Categorical(["p", "q", "p", "p", "q"]),
    })
    back = frame_from_json(json.loads(json.dumps(frame_to_json(frame))))
    pd.testing.assert_frame_equal(back, frame)
    assert np.signbit(back["x"].iloc[3])
    empty = frame.drop(columns="kind").iloc[:0]  # (an empty category keeps no categories)
    pd.testing.assert_frame_equal(frame_from_json(frame_to_json(empty)), empty,
                                  check_index_type=False)


def test_a_perturbation_session_skips_acf_with_its_reason():
    """The virtual set-up's protocol perturbs every fifth impact: no run of max_lag + 2
    unperturbed impacts, so acf is not run (a warning, not a failure of the unit: the docs'
    first virtual-to-study example exited 1); perturbations every 40 impacts leave runs."""
    from bounce_cli.analysis.data_stats import perturbation_schedule, simulate_impacts
    from bounce_cli.data.impacts import impacts_frame
    from bounce_cli.model.params import ModelParams

    params = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.3, racket_period=0.92)
    from bounce_cli.runtime.config import bundled_config_path

    cfg = load_config(study.StudyConfig, bundled_config_path("study")).model_dump(mode="json")
    for every, skipped in ((5, True), (40, False)):
        alpha = perturbation_schedule(2, 120, every, 0.5, [(0.4, 0.45), (0.55, 0.6)], seed=1)
        pooled = impacts_frame(simulate_impacts(params, 0.01, 0.01, 2, 120, seed=2,
                                                alpha=alpha), params)
        why = study.perturbations_leave_no_run(pooled, cfg, 0.5, 9.81, 1)
        assert bool(why) == skipped, (every, why)
    assert "no run of 12 consecutive unperturbed impacts" in study.perturbations_leave_no_run(
        impacts_frame(simulate_impacts(params, 0.01, 0.01, 2, 120, seed=2, alpha=(
            perturbation_schedule(2, 120, 5, 0.5, [(0.4, 0.45)], seed=1))), params),
        cfg, 0.5, 9.81, 1)


@pytest.mark.parametrize("n", [6, 12, 45])
def test_no_two_subjects_share_a_colour_and_marker(n):
    """group_learning.png gave s1 and s6 one colour (a five-colour cycle)."""
    from bounce_cli.experiments.study_figures import subject_styles

    styles = subject_styles([f"s{i}" for i in range(n)])
    assert len({(tuple(s["color"]), s["marker"]) for s in styles.values()}) == n


def test_a_recording_s_reading_error_names_the_study_s_key(tmp_path):
    # extraction errors said 'set columns.racket'; in a study that key is extract.columns...
    from bounce_cli.data.recordings import keys_in_block
    from bounce_cli.errors import ConfigError

    said = keys_in_block(ConfigError("f.csv: no column 'x' (the file has: a; set "
                                     "columns.racket); another separator? set csv.separator"),
                         "extract")
    assert str(said) == ("f.csv: no column 'x' (the file has: a; set extract.columns.racket); "
                         "another separator? set csv.separator".replace(
                             "set csv", "set extract.csv"))
    assert str(keys_in_block(ConfigError("a settings text"), "extract")) == "a settings text"
    bad = tmp_path / "lab.csv"
    bad.write_text("trial,time,racket,ball\n1,0.0,0.1,0.5\n1,0.01,0.1,0.5\n")
    (tmp_path / "study.csv").write_text("file,subject,condition\nlab.csv,s1,a\n")
    result = bounce_cli.run("study", set={"manifest": str(tmp_path / "study.csv"),
                                          "analyses": ["regression"]})
    error = result.frames["failures.csv"]["error"].iloc[0]
    assert "set extract.columns.time" in error, error


def test_stability_verdicts_are_read_over_the_table_s_tests():
    """group_stability.csv holds a paired test per estimator and condition. A review's
    simulated study (truth: the model) got 'data slower than the model' from one of eight
    (p 0.03 alone): a row whose interval excludes 0 now says whether the difference
    survives Holm's adjustment over the table's tests (p_value_holm)."""
    from bounce_cli.experiments.study import with_difference_verdicts

    p = [0.03, 0.001, 0.4, 0.6, 0.5, 0.7, 0.8, 0.9]
    table = pd.DataFrame({
        "units": [3] * 8 + [1],
        "ci_low": [0.009, 0.02, -0.01, -0.02, -0.01, -0.03, -0.02, -0.01, np.nan],
        "ci_high": [0.042, 0.05, 0.02, 0.01, 0.03, 0.02, 0.01, 0.02, np.nan],
        "p_value": p + [np.nan]})
    out = with_difference_verdicts(table, 0.95)
    assert out.verdict[0] == ("data slower than the model in this row alone; not after "
                              "Holm's adjustment over the table's 8 tests")
    assert out.verdict[1] == "data slower than the model"  # 0.001 x 8 < 0.05
    assert (out.verdict[2:8] == "no difference detected").all()
    assert out.verdict[8] == "too few units with an interval"
    assert out.p_value_holm[1] == pytest.approx(0.008)
    assert out.p_value_holm[0] == pytest.approx(min(1.0, 0.03 * 7))
    assert np.isnan(out.p_value_holm[8])


def test_impulse_on_units_without_perturbations_is_not_run_with_one_warning(tiny, tmp_path,
                                                                            cli_module):
    """impulse was skipped without a word for a unit whose impacts hold no perturbation,
    where the docs promise a warning (study.md's exit status, virtual.md). The same reason
    for every unit is one line, not one per unit."""
    out = tmp_path / "out"
    result = cli_module("study", "--manifest", tiny / "study.csv", "--out", out,
                        "--set", "analyses=[impulse]", "--figures", "none", *FAST)
    assert result.exit_code == 0, result.output
    said = [" ".join(line.split()) for line in result.stderr.split("warning:")[1:]]
    about = [line for line in said if "impulse: not run" in line]
    assert len(about) == 1, result.stderr
    assert "every unit (2)" in about[0] and "no perturbed impact" in about[0]
    assert "impulse: not run" in (out / "report.html").read_text()
    assert pd.read_csv(out / "failures.csv").empty


def test_condensed_warnings_name_the_units_that_share_a_message():
    from bounce_cli.experiments.study import condensed_warnings

    labels = ["s1/a", "s2/a", "s3/a", "s4/a", "s5/a"]
    warnings = [["s1/a: impulse: not run: none", "s1/a: acf: trial 2 short"],
                ["s2/a: impulse: not run: none"], ["s3/a: impulse: not run: none"],
                ["s4/a: impulse: not run: none", "a message of no unit"],
                ["s5/a: impulse: not run: none", "s5/a: acf: trial 2 short"]]
    assert condensed_warnings(labels, warnings) == [
        "every unit (5): impulse: not run: none", "2 units (s1/a, s5/a): acf: trial 2 short",
        "a message of no unit"]
    assert condensed_warnings(labels, [w[:1] for w in warnings[:4]] + [[]]) == [
        "4 units (s1/a, s2/a, s3/a and 1 more): impulse: not run: none"]
    assert condensed_warnings(["s1"], [["s1: x"]]) == ["s1: x"]


def test_group_csv_says_why_a_unit_has_no_relaxation():
    """group.csv's relax_impacts_* were NaN with no word where impulse did not run (no
    perturbations) or a direction had no perturbation, beside radius notes that say why (a
    data review): relax_impacts_note says it."""
    from bounce_cli.data.study_manifest import Unit
    from bounce_cli.experiments.study import unit_row

    pooled = pd.DataFrame({"trial": [1, 1, 1], "theta_rad": [0.7, 0.75, 0.8],
                           "v_m_s": [4.5, 4.4, 4.6]})
    unit = Unit(key=("s1", "a"), grouping=("subject", "condition"))
    why = "the unit's impacts hold no perturbed impact to align on"
    row = unit_row(pooled, {}, unit, None, {"impulse": why})
    assert np.isnan(row["relax_impacts_increase"])
    assert row["relax_impacts_note"] == f"impulse --data not run: {why}"
    relax = pd.DataFrame({"direction": ["decrease"], "source": ["data"],
                          "relaxation_impacts": [6.0]})
    row = unit_row(pooled, {"s1/a/impulse/relaxation_data.csv": relax}, unit, None, {})
    assert row["relax_impacts_decrease"] == 6.0 and np.isnan(row["relax_impacts_increase"])
    assert row["relax_impacts_note"] == "increase: no perturbation of that direction"
