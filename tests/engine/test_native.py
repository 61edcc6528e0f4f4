"""The basin kernel's machine code loaded without numba (``model.native``): the same outcome
and impact count as numba's dispatcher and the numpy code, point for point; numba not
imported on its way; and every guard that keeps wrong machine code from running (the key,
the checksum, the symbols, the check in a fresh process, the unusable mark)."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest

from bounce_cli.analysis.classify import ClassifySettings, classify_batch, passive_map
from bounce_cli.model.impact import MAX_SAFE_STEPS
from bounce_cli.model.kernel_arrays import solver_constants
from bounce_cli.model.params import ModelParams

pytest.importorskip("numba")
from bounce_cli.model import compiled, native  # noqa: E402

PARAMETERS = [
    ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92),
    ModelParams(alpha=0.0, g=9.81, racket_amplitude=0.20, racket_period=0.6),
    ModelParams(alpha=0.8, g=9.81, racket_amplitude=0.60, racket_period=0.92),
    ModelParams(alpha=0.3, g=5.8, racket_amplitude=0.10, racket_period=1.5),
]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The object built into a directory of its own (the same key as the installed one)."""
    folder = tmp_path_factory.mktemp("native")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(native, "cache_dirs", lambda: [folder])
        patch.delenv("BOUNCE_KERNEL", raising=False)
        native._classifier_once.cache_clear()
        try:
            assert native.build_classifier()
            loaded = native.classifier()
        finally:
            native._classifier_once.cache_clear()
    assert loaded is not None
    obj, meta, unusable = native._paths(folder, native.cache_key())
    return loaded, folder, obj, meta, unusable


def _fresh_load() -> bool:
    native._classifier_once.cache_clear()
    try:
        return native.classifier() is not None
    finally:
        native._classifier_once.cache_clear()


@pytest.mark.parametrize("params", PARAMETERS, ids=["fig4", "dead", "large", "slow"])
def test_the_machine_code_classifies_as_numba_and_numpy(built, params):
    loaded = built[0]
    rng = np.random.default_rng(5)
    theta = rng.uniform(-7.0, 14.0, 5000)  # unwrapped phases too
    v = rng.uniform(-1.0, 2.0 * params.g * params.racket_period, 5000)
    settings = ClassifySettings(max_iterations=60, tolerance=1e-3, min_hop_s=1e-3)
    by_numpy = classify_batch(theta, v, params, settings, require_fixed_point=False,
                              kernel="numpy")
    target = passive_map(params, require_fixed_point=False).target
    outcome, iterations = loaded(theta, v, solver_constants(params, target, 1e-3, 1e-3), 60,
                                 MAX_SAFE_STEPS)
    np.testing.assert_array_equal(outcome, by_numpy.outcome)
    np.testing.assert_array_equal(iterations, by_numpy.iterations)
    by_numba = compiled.classify_arrays(theta, v, params, target, 60, 1e-3, 1e-3,
                                        MAX_SAFE_STEPS)
    np.testing.assert_array_equal(outcome, by_numba[0])
    np.testing.assert_array_equal(iterations, by_numba[1])
    assert len(set(np.unique(outcome))) >= 2  # more than one branch was compared


def test_the_object_refers_only_to_numba_s_helpers_cpython_and_the_c_library(built):
    meta = json.loads(built[3].read_text())
    assert native.undefined_symbols(built[2].read_bytes()) == meta["undefined"]
    assert {"cos", "sin"} <= set(meta["undefined"])  # the launch test's C library functions
    assert native._symbol_addresses(meta["undefined"]) is not None
    assert native._symbol_addresses(meta["undefined"] + ["no_such_symbol_here"]) is None
    assert native.undefined_symbols(b"MZ" + bytes(100)) is None  # not ELF: numba's dispatcher


def test_a_changed_file_another_key_or_a_mark_keeps_the_object_from_loading(built, monkeypatch,
                                                                           tmp_path):
    _, folder, obj, meta, unusable = built
    monkeypatch.setattr(native, "cache_dirs", lambda: [tmp_path])
    monkeypatch.delenv("BOUNCE_KERNEL", raising=False)
    copy_obj, copy_meta, copy_unusable = native._paths(tmp_path, native.cache_key())
    loads = _fresh_load
    copy_obj.write_bytes(obj.read_bytes())
    copy_meta.write_text(meta.read_text())
    assert loads()
    monkeypatch.setenv("BOUNCE_KERNEL", "numba")  # numba's dispatcher asked for
    assert not loads()
    monkeypatch.delenv("BOUNCE_KERNEL")
    code = bytearray(obj.read_bytes())
    code[len(code) // 2] ^= 1  # one bit changed: the checksum refuses it
    copy_obj.write_bytes(bytes(code))
    assert not loads()
    copy_obj.write_bytes(obj.read_bytes())
    monkeypatch.setenv("NUMBA_OPT", "1")  # another numba setting: another key
    assert not loads()
    monkeypatch.delenv("NUMBA_OPT")
    copy_unusable.write_text("the check's outcomes differ from numba's\n")
    assert not loads()


def test_a_check_that_disagrees_with_numba_fails(built):
    _, _, obj, meta, _ = built
    expected = native._classify_check_grids(compiled.classify_arrays)
    assert native._verify(obj, meta, expected) == (True, "")
    passed, reason = native._verify(obj, meta, expected.replace("0", "1", 1))
    assert not passed and "differ" in reason


def test_a_basin_with_the_machine_code_does_not_import_numba(built, tmp_path):
    """The point of the route: a whole basin classified in threads, numba never imported."""
    _, folder, *_ = built
    script = (
        "import sys\n"
        "from pathlib import Path\n"
        "from bounce_cli.model import native\n"
        f"native.cache_dirs = lambda: [Path({str(folder)!r})]\n"
        "import numpy as np\n"
        "from bounce_cli.analysis.classify import load_compiled_kernel\n"
        "from bounce_cli.experiments.basin import classify_map_grid\n"
        "from bounce_cli.analysis.classify import passive_map, ClassifySettings\n"
        "from bounce_cli.model.params import ModelParams\n"
        "p = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.3, racket_period=0.92)\n"
        "th, v = np.meshgrid(np.linspace(0, 6.28, 400), np.linspace(0, 10, 300))\n"
        "r = classify_map_grid(th, v, passive_map(p), ClassifySettings(), jobs=2)\n"
        "print('numba' in sys.modules, np.bincount(r.outcome.ravel()).tolist())\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env=_without_kernel_choice())
    assert done.returncode == 0, done.stderr
    imported, counts = done.stdout.split(" ", 1)
    assert imported == "False"
    th, v = np.meshgrid(np.linspace(0, 6.28, 400), np.linspace(0, 10, 300))
    expected = classify_batch(th, v, PARAMETERS[0], kernel="numpy")
    assert json.loads(counts) == np.bincount(expected.outcome.ravel()).tolist()


def _without_kernel_choice():
    import os

    return {k: v for k, v in os.environ.items() if k != "BOUNCE_KERNEL"}


def test_where_the_object_cannot_be_used_the_key_is_marked_and_never_compiled_again(
        monkeypatch, tmp_path):
    """Not ELF (macOS, Windows) or numba refusing the entry: marked unusable once, so that a
    later run neither compiles it again (a second of every basin's start-up) nor fails."""
    monkeypatch.setattr(native, "cache_dirs", lambda: [tmp_path])
    monkeypatch.delenv("BOUNCE_KERNEL", raising=False)
    native._classifier_once.cache_clear()
    key = native.cache_key()
    marker = native._paths(tmp_path, key)[2]
    compiles = []

    def not_elf(key):
        compiles.append(key)
        return b"\xcf\xfa\xed\xfe", None  # a Mach-O object's magic

    monkeypatch.setattr(native, "_compile_entry", not_elf)
    try:
        assert not native.build_classifier()
        assert "ELF" in marker.read_text()
        assert not native.build_classifier()  # marked: not compiled again
        assert len(compiles) == 1
        marker.unlink()

        def refusing(key):
            raise RuntimeError("numba refused")

        monkeypatch.setattr(native, "_compile_entry", refusing)
        assert not native.build_classifier()
        assert "numba refused" in marker.read_text()
        assert native.classifier() is None
    finally:
        native._classifier_once.cache_clear()


@pytest.mark.parametrize("damage", [
    "[]", "null", '"text"', "json_symbol_int", "json_symbol_non_ascii", "json_undefined_nested",
    "json_undefined_empty", "json_undefined_one_less", "garbage_with_its_checksum",
    "not json {"])
def test_damaged_metadata_or_object_never_crashes_and_falls_back(built, monkeypatch, tmp_path,
                                                                damage):
    """A review's hand-damaged files (a metadata file of the wrong shape, an undefined-symbol
    list that leaves a symbol unbound with the object's checksum intact: a segmentation fault
    at the first call before) are refused: numba's dispatcher runs."""
    _, _, obj, meta, _ = built
    monkeypatch.setattr(native, "cache_dirs", lambda: [tmp_path])
    monkeypatch.delenv("BOUNCE_KERNEL", raising=False)
    copy_obj, copy_meta, _ = native._paths(tmp_path, native.cache_key())
    code, record = obj.read_bytes(), json.loads(meta.read_text())
    text = None
    if damage == "json_symbol_int":
        record["symbol"] = 5
    elif damage == "json_symbol_non_ascii":
        record["symbol"] = "entr\u00e9e"
    elif damage == "json_undefined_nested":
        record["undefined"] = [record["undefined"]]
    elif damage == "json_undefined_empty":
        record["undefined"] = []
    elif damage == "json_undefined_one_less":
        record["undefined"] = [n for n in record["undefined"] if n != "numba_gil_ensure"]
    elif damage == "garbage_with_its_checksum":
        code = bytes(range(256)) * 40
        record["sha256"] = hashlib.sha256(code).hexdigest()
    else:
        text = damage
    copy_obj.write_bytes(code)
    copy_meta.write_text(text if text is not None else json.dumps(record))
    assert not _fresh_load()


def test_a_damaged_first_directory_does_not_hide_a_good_second(built, monkeypatch, tmp_path):
    _, _, obj, meta, _ = built
    first, second = tmp_path / "first", tmp_path / "second"
    monkeypatch.setattr(native, "cache_dirs", lambda: [first, second])
    monkeypatch.delenv("BOUNCE_KERNEL", raising=False)
    key = native.cache_key()
    for folder in (first, second):
        folder.mkdir()
        paths = native._paths(folder, key)
        paths[0].write_bytes(obj.read_bytes())
        paths[1].write_text(meta.read_text())
    damaged = bytearray(obj.read_bytes())
    damaged[100] ^= 1
    native._paths(first, key)[0].write_bytes(bytes(damaged))
    assert _fresh_load()


def test_a_broken_llvmlite_or_no_home_directory_falls_back_to_numba(monkeypatch):
    """Anything failing on the native route (here llvmlite's library not loading, a user
    without a home directory) leaves the run to numba's dispatcher, as BOUNCE_KERNEL=numba
    would: a review's broken llvmlite ended every basin, sweep and attractors run."""
    from pathlib import Path

    from bounce_cli.analysis import classify as classify_module

    monkeypatch.delenv("BOUNCE_KERNEL", raising=False)

    def broken():
        raise OSError("Could not find/load shared object file 'libllvmlite.so'")

    monkeypatch.setattr(native, "cache_key", broken)
    assert not _fresh_load()
    assert not native.build_classifier()
    assert classify_module.compiled_kernel_available()  # numba's dispatcher
    theta, v = np.meshgrid(np.linspace(0, 6.3, 20), np.linspace(0, 8, 20))
    assert (classify_batch(theta, v, PARAMETERS[0], kernel="compiled").outcome
            == classify_batch(theta, v, PARAMETERS[0], kernel="numpy").outcome).all()
    monkeypatch.undo()
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)

    def homeless():
        raise RuntimeError("Could not determine home directory")

    monkeypatch.setattr(Path, "home", staticmethod(homeless))
    assert native.cache_dirs() == [Path(native.__file__).parent / "__pycache__"]


def test_bounce_kernel_values(monkeypatch, cli, user_error, tmp_path):
    for value, choice in (("", "auto"), (" AUTO ", "auto"), ("numba", "numba"),
                          ("NumPy", "numpy")):
        monkeypatch.setenv("BOUNCE_KERNEL", value)
        assert native.kernel_choice() == choice
    monkeypatch.setenv("BOUNCE_KERNEL", "fast")
    user_error(cli("basin", "--quiet", "--set", "grid.theta0_deg.num=400", "--set",
                   "grid.v0_m_s.num=300", "--out", tmp_path / "b"),
               "BOUNCE_KERNEL='fast'", "auto, numba, numpy")


def test_no_writable_cache_directory_compiles_nothing(monkeypatch, tmp_path):
    """Nowhere to save it (a read-only installation, no cache directory): nothing is compiled
    (a review: a second of every run compiled and thrown away)."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")  # no folder can be made under a file, not even by root
    monkeypatch.setattr(native, "cache_dirs", lambda: [blocker / "bounce"])
    monkeypatch.delenv("BOUNCE_KERNEL", raising=False)
    monkeypatch.setattr(native, "_compile_entry", lambda key: pytest.fail("compiled"))
    assert native._writable_cache_dir() is None
    assert not native.build_classifier()


def test_the_check_runs_this_bounce_cli_whatever_the_working_directory_holds(built, tmp_path,
                                                                             monkeypatch):
    """The check's child is isolated: a bounce_cli (or a module shadowing the standard
    library) in the working directory is not imported (a review: an old checkout there
    marked the key unusable for good)."""
    _, _, obj, meta, _ = built
    decoy = tmp_path / "bounce_cli"
    decoy.mkdir()
    (decoy / "__init__.py").write_text("raise ImportError('the wrong bounce_cli')\n")
    (tmp_path / "enum.py").write_text("raise ImportError('a shadowed standard library')\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    expected = native._classify_check_grids(compiled.classify_arrays)
    assert native._verify(obj, meta, expected) == (True, "")


def test_numba_s_settings_file_in_the_working_directory_is_part_of_the_key(monkeypatch,
                                                                          tmp_path):
    monkeypatch.chdir(tmp_path)
    before = native.cache_key()
    (tmp_path / ".numba_config.yaml").write_text("cpu_name: generic\n")
    assert native.cache_key() != before
