"""The basin kernel's machine code loaded without numba (``model.native``): the same outcome
and impact count as numba's dispatcher and the numpy code, point for point; numba not
imported on its way; and every guard that keeps wrong machine code from running (the key,
the checksum, the symbols, the check in a fresh process, the unusable mark)."""

from __future__ import annotations

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
        native.classifier.cache_clear()
        try:
            assert native.build_classifier()
            loaded = native.classifier()
        finally:
            native.classifier.cache_clear()
    assert loaded is not None
    obj, meta, unusable = native._paths(folder, native.cache_key())
    return loaded, folder, obj, meta, unusable


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

    def loads() -> bool:
        native.classifier.cache_clear()
        try:
            return native.classifier() is not None
        finally:
            native.classifier.cache_clear()

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
    native.classifier.cache_clear()
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
        native.classifier.cache_clear()
