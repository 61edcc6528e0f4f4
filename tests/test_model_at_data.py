"""The model at the data's parameters is built in one place (``data_parameters.model_at_data``):
``acf``, ``impulse`` and ``control --data`` and a study's unit report the same model (alpha,
g, the data's mean racket amplitude and period) for the same impacts, and no experiment builds
it from the racket columns itself."""

import ast
import json
import math
from pathlib import Path

import pandas as pd
import pytest

import bounce_cli
from bounce_cli.data import data_parameters
from bounce_cli.data.impacts import Impacts
from bounce_cli.experiments import control, data_side, study
from bounce_cli.model.linear import jacobian, stability
from bounce_cli.model.params import ModelParams

EXPERIMENTS = Path(bounce_cli.__file__).parent / "experiments"

#: one subject, one condition, three perturbed trials
SIM = ["--set", "subjects.count=1", "--set", "conditions=[{name: a}]", "--set", "trials=3",
       "--set", "duration_s=20", "--set", "perturbations.every=25",
       "--set", "perturbations.alphas=[0.4, 0.6]"]
#: acf --data's trust study at a small size
FAST_ACF = ["--set", "data_analysis.trust_repetitions=10",
            "--set", "data_analysis.trust_bounces=[100]"]
#: a racket far from the simulated lab's (about 0.096 m, 0.575 s)
FAR_RACKET = ["--set", "model.racket_amplitude=0.30", "--set", "model.racket_period=0.92"]
REL = 1e-12


@pytest.fixture(scope="module")
def built():
    """Every model ``model_at_data`` builds while the module's fixtures run: (where, params)."""
    seen: list[tuple[str, ModelParams]] = []
    original = data_parameters.model_at_data

    def spy(impacts, found, *args, **kwargs):
        params = original(impacts, found, *args, **kwargs)
        seen.append((str(impacts.path), params))
        return params

    with pytest.MonkeyPatch.context() as patch:
        for module in (data_side, control, study):
            patch.setattr(module, "model_at_data", spy)
        yield seen


@pytest.fixture(scope="module")
def unit(tmp_path_factory, cli, built):
    """A study of one unit (alpha and g its data's) with acf, impulse and control; the unit's
    pooled impacts.csv; and the --data analyses of that file at the unit's g."""
    root = tmp_path_factory.mktemp("model-at-data")
    result = cli("simulate-study", "--quiet", "--out", root / "sim", *SIM)
    assert result.exit_code == 0, result.output
    result = cli("study", "--manifest", root / "sim" / "study.csv", "--out",
                        root / "study", "--jobs", "1", "--quiet",
                        "--set", "analyses=[acf, impulse, control]",
                        "--set", "settings.acf.data_analysis.trust_repetitions=10",
                        "--set", "settings.acf.data_analysis.trust_bounces=[100]")
    assert result.exit_code == 0, result.output
    group = pd.read_csv(root / "study" / "group.csv")
    assert len(group) == 1
    row = group.iloc[0]
    assert row["alpha_source"].startswith("measured") and row["g_source"].startswith("measured")
    folder = root / "study" / str(row["subject"]) / str(row["condition"])
    impacts = folder / "impacts.csv"
    runs = {}  # g and the measurement noise from the unit's setup.csv beside the table
    for name, extra in (("acf", FAST_ACF), ("impulse", []), ("control", [])):
        out = root / name
        result = cli(name, "--data", impacts, "--out", out, "--quiet", *FAR_RACKET, *extra)
        assert result.exit_code == 0, result.output
        runs[name] = out
    return {"row": row, "folder": folder, "impacts": impacts, "runs": runs}


def close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=REL, abs_tol=0.0)


def same(a: ModelParams, b: ModelParams) -> bool:
    return all(close(x, y) for x, y in zip(
        (a.alpha, a.g, a.racket_amplitude, a.racket_period),
        (b.alpha, b.g, b.racket_amplitude, b.racket_period)))


def unit_model(unit) -> ModelParams:
    """The unit's model as group.csv states it: alpha, g and the data's mean racket."""
    row = unit["row"]
    return ModelParams(float(row["alpha"]), float(row["g_m_s2"]),
                       float(row["racket_amplitude_mean_m"]), float(row["racket_period_mean_s"]))


@pytest.mark.slow
def test_the_datas_racket_is_the_mean_of_its_columns_not_the_configs(unit):
    frame = pd.read_csv(unit["impacts"])
    expected = unit_model(unit)
    assert close(expected.racket_amplitude, float(frame["racket_amplitude_m"].mean()))
    assert close(expected.racket_period, float(frame["racket_period_s"].mean()))
    # far from the configs' 0.30 m / 0.92 s: a model at the config's racket would show
    assert abs(expected.racket_amplitude - 0.30) > 0.1
    assert abs(expected.racket_period - 0.92) > 0.2


@pytest.mark.slow
def test_every_model_built_is_the_units(unit, built):
    """Each call of model_at_data (the study's unit row and analyses, and the three --data
    commands on the unit's file) gave the same alpha, g, a_r and tau."""
    expected = unit_model(unit)
    where = {w for w, _ in built}
    assert str(unit["impacts"]) in where and len(where) == 2  # the file and the unit in memory
    assert len(built) == 7  # the study's row, its 3 analyses, the 3 commands
    for w, params in built:
        assert same(params, expected), (w, params, expected)


@pytest.mark.slow
def test_the_group_row_holds_the_model_and_its_eq10_radius(unit):
    expected = unit_model(unit)
    assert close(float(unit["row"]["model_spectral_radius"]),
                 stability(expected).spectral_radius)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["acf", "impulse", "control"])
def test_run_json_records_the_units_alpha_and_g(unit, name):
    recorded = json.loads((unit["runs"][name] / "run.json").read_text())["model_at_data"]
    row = unit["row"]
    assert recorded["alpha"]["source"] == "measured"
    assert close(recorded["alpha"]["value"], float(row["alpha"]))
    assert recorded["g"]["source"] == "measured"  # the unit's setup.csv
    assert close(recorded["g"]["value"], float(row["g_m_s2"]))
    # and the racket: the data's, not the config's 0.30 m / 0.92 s
    for key, column in (("racket_amplitude", "racket_amplitude_mean_m"),
                        ("racket_period", "racket_period_mean_s")):
        assert recorded[key]["source"] == "data"
        assert close(recorded[key]["value"], float(row[column])), key


@pytest.mark.slow
@pytest.mark.parametrize("name, table", [("acf", "stability_data.csv"),
                                         ("acf", "trust.csv"),
                                         ("impulse", "aligned.csv")])
def test_a_command_on_the_units_table_writes_what_the_study_wrote(unit, name, table):
    """The unit's folder stands alone: ``bounce <name> --data <unit>/impacts.csv`` takes g
    and the measurement noise from the setup.csv the study wrote beside it, so its tables
    are the study's (a study that wrote no setup.csv would leave g to be set by hand and the
    trust study at the assumed noise: other intervals). The numbers only: a note naming
    where alpha came from says ``config`` in the study, whose analyses get the unit's alpha
    in their config, and ``measured`` in the command."""
    ours = pd.read_csv(unit["runs"][name] / table)
    studys = pd.read_csv(unit["folder"] / name / table)
    numbers = ours.select_dtypes("number").columns
    assert list(numbers) == list(studys.select_dtypes("number").columns) and len(numbers)
    pd.testing.assert_frame_equal(ours[numbers], studys[numbers], check_exact=False,
                                  rtol=1e-12)


def stability_model_rows(path: Path) -> dict[str, float]:
    frame = pd.read_csv(path)
    rows = frame[frame["source"].isin(["model_eq9", "model_eq10"])]
    return dict(zip(rows["quantity"], rows["estimate"]))


@pytest.mark.slow
def test_acf_outputs_are_eq9_and_eq10_at_the_units_model(unit):
    """acf --data's model rows (the command's and the study's analysis of the unit) are eq. 9's
    J and eq. 10's radius at the unit's model, not at the config's racket."""
    expected = unit_model(unit)
    J = jacobian(expected)
    for path in (unit["runs"]["acf"] / "stability_data.csv",
                 unit["folder"] / "acf" / "stability_data.csv"):
        rows = stability_model_rows(path)
        for name, value in (("J_vv", J[0, 0]), ("J_vtheta", J[0, 1]), ("J_thetav", J[1, 0]),
                            ("spectral_radius", stability(expected).spectral_radius)):
            assert math.isclose(rows[name], value, rel_tol=1e-9), (path, name)


@pytest.mark.slow
def test_control_fit_states_the_units_model(unit):
    """control --data's fit.csv (the command's and the study's) holds alpha_0 and the data's
    racket, not the config's 0.30 m / 0.92 s."""
    expected = unit_model(unit)
    for path in (unit["runs"]["control"] / "fit.csv", unit["folder"] / "control" / "fit.csv"):
        fit = pd.read_csv(path).set_index("quantity")["estimate"]
        assert close(float(fit["model_alpha_0"]), expected.alpha), path
        assert close(float(fit["model_racket_amplitude"]), expected.racket_amplitude), path
        assert close(float(fit["model_racket_period"]), expected.racket_period), path


@pytest.mark.slow
def test_impulse_model_response_is_about_the_units_fixed_point(unit):
    """impulse --data's model response (the command's and the study's) is a deviation from the
    fixed point of the unit's model: v~ = pi g / omega_r (eq. 7) and theta~ (eq. 8, which the
    racket amplitude and alpha enter)."""
    fixed = unit_model(unit).fixed_point()
    for path in (unit["runs"]["impulse"] / "model_response.csv",
                 unit["folder"] / "impulse" / "model_response.csv"):
        frame = pd.read_csv(path)
        v = frame["v_m_s"] - frame["dv_m_s"]
        theta = (frame["theta_deg"] - frame["dtheta_deg"] + 180.0) % 360.0 - 180.0
        assert all(math.isclose(x, fixed.v_m_s, rel_tol=1e-9) for x in v), path
        assert all(math.isclose(x, math.degrees(fixed.theta_rad), rel_tol=1e-9)
                   for x in theta), path


@pytest.mark.slow
@pytest.mark.parametrize("name", ["acf", "impulse", "control"])
def test_a_model_without_a_fixed_point_is_the_same_one_line(unit, cli, user_error, name):
    """alpha 0.05 at the unit's racket: eq. 8 has no solution; each command says so in the
    same words (control before its own fixed-point check did)."""
    result = cli(name, "--data", unit["impacts"], "--out", unit["impacts"].parent / f"no-{name}",
                 "--quiet", "--set", "model.alpha=0.05", "--set", "model.g=9.81", *FAR_RACKET)
    user_error(result, "the model at the data's racket amplitude ",
               "has no period-1 fixed point (eq. 8: cos theta~ = ")


def test_control_takes_a_given_racket_period_and_the_datas_amplitude():
    """``fit.racket_period_s`` replaces the data's mean period only; a model without a fixed
    point is one line naming eq. 8, whoever asks."""
    frame = pd.DataFrame({"racket_amplitude_m": [0.25, 0.35], "racket_period_s": [0.85, 0.95]})
    impacts = Impacts(frame, Path("lab.csv"))
    found = data_parameters.DataModel(data_parameters.ModelValue("alpha", 0.5, "set"),
                                      data_parameters.ModelValue("g", 9.81, "set"))
    params = data_parameters.model_at_data(impacts, found, need="fixed point",
                                           racket_period=0.92)
    assert (params.racket_amplitude, params.racket_period) == (pytest.approx(0.30), 0.92)
    assert data_parameters.model_at_data(impacts, found).racket_period == pytest.approx(0.90)
    weak = data_parameters.DataModel(data_parameters.ModelValue("alpha", 0.05, "set"),
                                     found.g)
    with pytest.raises(data_parameters.ConfigError, match=r"no period-1 fixed point \(eq. 8"):
        data_parameters.model_at_data(impacts, weak, need="fixed point")
    assert data_parameters.model_at_data(impacts, weak, need=None).alpha == 0.05


# -- no experiment builds the model from the racket columns itself ----------------------------
def racket_column_read(node: ast.AST) -> bool:
    """``x["racket_amplitude..."]`` or ``x["racket_period..."]`` (a column, a mean's key)."""
    return (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
            and isinstance(node.slice.value, str)
            and node.slice.value.startswith(("racket_amplitude", "racket_period")))


def builds_model_from_racket_columns(source: str) -> list[str]:
    """The functions of ``source`` that construct ``ModelParams(`` and also read a racket
    column (in the call or elsewhere in the function): each is a second home of the model at
    the data's parameters."""
    found = []
    for func in ast.walk(ast.parse(source)):
        if not isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        nodes = list(ast.walk(func))
        constructs = any(isinstance(n, ast.Call) and getattr(n.func, "id", None) == "ModelParams"
                         for n in nodes)
        if constructs and any(racket_column_read(n) for n in nodes):
            found.append(func.name)
    return found


def test_the_check_catches_the_model_built_by_hand():
    """The way control and study built it before: the check names both."""
    by_hand = '''
def fit_inputs(impacts, model, period):
    return ModelParams(model.alpha.value, model.g.value,
                       float(impacts["racket_amplitude_m"].mean()),
                       float(impacts["racket_period_s"].mean()) if period is None else period)

def unit_row(out, alpha, g):
    tau = out["racket_period_mean_s"]
    return ModelParams(alpha, g, out["racket_amplitude_mean_m"], tau)
'''
    assert builds_model_from_racket_columns(by_hand) == ["fit_inputs", "unit_row"]


def test_no_experiment_builds_the_model_at_the_datas_racket_itself():
    offenders = {path.name: names for path in sorted(EXPERIMENTS.rglob("*.py"))
                 if (names := builds_model_from_racket_columns(path.read_text()))}
    assert offenders == {}, ("build the model at the data's parameters with "
                             "data_parameters.model_at_data")
