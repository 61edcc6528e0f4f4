"""The errors module (``bounce_cli.errors``): one base class a Python caller catches, classes
that tell the errors apart, the CLI printing every one of them as one line, and no branch on
an error message's text."""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import bounce_cli
from bounce_cli import errors
from bounce_cli.cli.commands import app

PACKAGE = Path(bounce_cli.__file__).parent
#: exception classes of the package that are deliberately not BounceErrors (errors.py says why)
NOT_BOUNCE_ERRORS = {
    # a BaseException: ``except Exception`` lets it by
    "bounce_cli.runtime.interrupts.Interrupted",
    # a worker's traceback: a bug report, not a user error
    "bounce_cli.runtime.parallel.WorkerError",
    # a forked lane killed outright (the out-of-memory killer): an OSError of the machine,
    # which `bounce reproduce` reports as one line naming the experiment
    "bounce_cli.runtime.forked.LaneDied",
    "bounce_cli.runtime.config.DuplicateKeyError",  # a yaml.YAMLError, turned into a ConfigError
}
ERROR_CLASSES = [getattr(errors, name) for name in errors.__all__]


def package_modules() -> list[str]:
    """Every module of the package but ``__main__`` (importing it runs the command)."""
    return [info.name for info in pkgutil.walk_packages([str(PACKAGE)], "bounce_cli.")
            if not info.name.endswith("__main__")]


def defined_exception_classes() -> dict[str, type]:
    """Every exception class defined (not merely imported) in a module of the package."""
    found = {}
    for name in package_modules():
        module = importlib.import_module(name)
        for value in vars(module).values():
            if (inspect.isclass(value) and issubclass(value, BaseException)
                    and value.__module__ == name):
                found[f"{name}.{value.__qualname__}"] = value
    return found


def test_every_exception_class_of_the_package_is_a_bounce_error_or_says_why_not():
    classes = defined_exception_classes()
    assert set(NOT_BOUNCE_ERRORS) <= set(classes)  # the exceptions still exist
    strays = [name for name, cls in classes.items()
              if name not in NOT_BOUNCE_ERRORS and not issubclass(cls, errors.BounceError)]
    assert strays == []
    # one home: every BounceError is defined in bounce_cli.errors
    homes = {name for name, cls in classes.items() if issubclass(cls, errors.BounceError)}
    assert homes == {f"bounce_cli.errors.{cls.__name__}" for cls in ERROR_CLASSES}


@pytest.mark.parametrize("module, name", [
    ("bounce_cli.runtime.config", "ConfigError"),
    ("bounce_cli.model.params", "ModelError"),
    ("bounce_cli.model.params", "NoFixedPointError"),
    ("bounce_cli.runtime.artifacts", "OutputDirError"),
    ("bounce_cli.runtime.parallel", "ClusterError"),
    ("bounce_cli.reproduction.claims", "MissingResults"),
    ("bounce_cli.api", "ConfigError"),
    ("bounce_cli", "BounceError"),
    ("bounce_cli", "ConfigError"),
    ("bounce_cli", "ModelError"),
])
def test_the_old_names_import_the_one_class(module, name):
    assert getattr(importlib.import_module(module), name) is getattr(errors, name)


@pytest.mark.parametrize("cls", ERROR_CLASSES, ids=lambda c: c.__name__)
def test_each_error_is_a_bounce_error_and_keeps_its_builtin_base(cls):
    assert issubclass(cls, errors.BounceError) and issubclass(cls, Exception)
    builtin = {errors.BounceError: Exception, errors.ClusterError: RuntimeError,
               errors.MissingResults: Exception}
    assert issubclass(cls, builtin.get(cls, ValueError))
    assert cls.__doc__  # errors.py's tree names what each means


def test_the_hierarchy_a_caller_relies_on():
    assert issubclass(errors.NoFixedPointError, errors.ModelError)
    assert issubclass(errors.NotStableError, errors.ModelError)
    assert issubclass(errors.NoPerturbedImpactError, errors.DataError)
    assert issubclass(errors.NoPerturbedImpactError, errors.ModelError)  # as raised before
    assert issubclass(errors.RunDirectoryBusy, errors.OutputDirError)
    assert not issubclass(errors.ConfigError, errors.ModelError)
    assert not issubclass(errors.DataError, errors.ConfigError)


def test_errors_imports_only_the_standard_library():
    tree = ast.parse((PACKAGE / "errors.py").read_text())
    imported = {alias.name.split(".")[0] for node in ast.walk(tree)
                if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module.split(".")[0] for node in ast.walk(tree)
                 if isinstance(node, ast.ImportFrom) and node.module and not node.level}
    assert imported <= {"__future__"}
    assert not [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level]


# -- raised where they mean something ---------------------------------------------------------
def test_a_python_caller_catches_an_unknown_experiment_as_a_bounce_error():
    with pytest.raises(bounce_cli.BounceError, match="no experiment named 'nosuch'") as info:
        bounce_cli.run("nosuch")
    assert isinstance(info.value, bounce_cli.ConfigError)


def test_parameters_without_a_fixed_point_are_a_no_fixed_point_error():
    params = bounce_cli.ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.01, racket_period=0.92)
    with pytest.raises(bounce_cli.BounceError) as info:
        params.fixed_point()
    assert type(info.value) is errors.NoFixedPointError


def test_an_unstable_linearisation_has_no_stationary_covariance():
    from bounce_cli.analysis.stochastic import stationary_covariance

    jac = np.array([[0.5, 0.0], [0.0, -1.25]])  # spectral radius 1.25
    with pytest.raises(errors.NotStableError, match="spectral radius 1.25"):
        stationary_covariance(jac, np.eye(2))
    assert stationary_covariance(np.diag([0.5, -0.5]), np.eye(2))[0, 0] == pytest.approx(4 / 3)


def test_impacts_without_a_perturbed_one_are_a_no_perturbed_impact_error():
    from bounce_cli.analysis.data_stats import align

    values = [np.linspace(1.0, 2.0, 12)]
    perturbed = [np.zeros(12, bool)]
    with pytest.raises(errors.NoPerturbedImpactError):
        align(values, perturbed, [np.full(12, 0.5)], n_after=3, settle=2)
    perturbed[0][4] = True  # one perturbation: its window
    assert align(values, perturbed, [np.full(12, 0.5)], n_after=3, settle=2).values.shape == (1, 4)


def test_a_held_run_directory_lock_is_run_directory_busy(tmp_path):
    pytest.importorskip("fcntl")
    from bounce_cli.runtime.artifacts import RunDirectoryLock

    holder = RunDirectoryLock(tmp_path)
    holder.acquire("basin")
    try:
        with pytest.raises(errors.RunDirectoryBusy, match="another bounce run is writing"):
            RunDirectoryLock(tmp_path).acquire("basin")
    finally:
        holder.release()


# -- the command line: every BounceError is one line and exit 2 ------------------------------
runner = CliRunner()


@pytest.mark.parametrize("cls", ERROR_CLASSES, ids=lambda c: c.__name__)
def test_the_cli_prints_any_bounce_error_of_an_experiment_as_one_line(monkeypatch, tmp_path, cls):
    def check_model(*args, **kwargs):
        raise cls("what to change")

    monkeypatch.setattr("bounce_cli.experiments.runner.check_model", check_model)
    result = runner.invoke(app, ["basin", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    assert result.stderr.splitlines() == ["bounce: error: what to change"]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("cls", [errors.ConfigError, errors.ModelError, errors.DataError])
def test_the_cli_prints_a_bounce_error_of_an_engine_command_as_one_line(monkeypatch, cls):
    def load_model_block(*args, **kwargs):
        raise cls("what to change")

    monkeypatch.setattr("bounce_cli.experiments.runner.load_model_block", load_model_block)
    result = runner.invoke(app, ["fixed-point"])
    assert result.exit_code == 2, result.output
    assert result.stderr.splitlines() == ["bounce: error: what to change"]


def test_an_error_that_is_not_a_bounce_error_is_not_dressed_as_a_user_error(monkeypatch, tmp_path):
    def check_model(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr("bounce_cli.experiments.runner.check_model", check_model)
    result = runner.invoke(app, ["basin", "--out", str(tmp_path / "o")])
    assert isinstance(result.exception, ZeroDivisionError)
    assert "bounce: error" not in result.stderr


# -- no control flow on an error message's text -----------------------------------------------
#: branches on a message's text allowed (file -> count): none are left
MESSAGE_BRANCHES_TO_REPLACE: dict[str, int] = {}


def branches_on_message_text(tree: ast.AST) -> int:
    """``... in str(exc)`` / ``exc.args[0] ...`` inside an ``except ... as exc`` block."""
    count = 0
    for handler in ast.walk(tree):
        if not (isinstance(handler, ast.ExceptHandler) and handler.name):
            continue
        for node in ast.walk(ast.Module(body=handler.body, type_ignores=[])):
            is_str_of_exc = (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                             and node.func.id == "str" and len(node.args) == 1
                             and isinstance(node.args[0], ast.Name)
                             and node.args[0].id == handler.name)
            is_args_of_exc = (isinstance(node, ast.Attribute) and node.attr == "args"
                              and isinstance(node.value, ast.Name)
                              and node.value.id == handler.name)
            if not (is_str_of_exc or is_args_of_exc):
                continue
            parents = [n for n in ast.walk(handler) if isinstance(n, ast.Compare)
                       and any(c is node for c in ast.walk(n))]
            count += bool(parents)
    return count


def test_no_branch_on_an_error_message_text():
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        count = branches_on_message_text(ast.parse(path.read_text()))
        if count:
            found[path.relative_to(PACKAGE).as_posix()] = count
    for name, count in found.items():
        assert count <= MESSAGE_BRANCHES_TO_REPLACE.get(name, 0), name


def test_the_message_branch_detector_sees_one():
    code = ("try:\n    f()\nexcept ValueError as exc:\n"
            "    if 'no perturbed impact' in str(exc):\n        pass\n")
    assert branches_on_message_text(ast.parse(code)) == 1
    quiet = "try:\n    f()\nexcept ValueError as exc:\n    print(str(exc))\n"
    assert branches_on_message_text(ast.parse(quiet)) == 0
