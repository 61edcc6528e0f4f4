"""The compiled basin kernel (engine.compiled, numba) against the numpy code it mirrors: the
same outcome and impact count for every point, the same first-impact phase to the last bit,
on grids, on random states at random parameters and on the edge cases; and the tool without
it (BOUNCE_KERNEL=numpy, numba missing)."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from bounce_cli.analysis import classify as classify_module
from bounce_cli.analysis.classify import ClassifySettings, classify_batch, classify_grid
from bounce_cli.model.impact import first_impact_phase
from bounce_cli.model.trig import sincos
from bounce_cli.model.params import ModelParams

pytest.importorskip("numba")
from bounce_cli.model import compiled  # noqa: E402

#: parameter sets: Fig. 4's; a nearly rigid bounce (alpha 0.95) and a dead one (alpha 0, grazing
#: possible); a large amplitude (period doubling, chaos); a slow racket, a fast one
PARAMETERS = [
    ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92),
    ModelParams(alpha=0.95, g=9.81, racket_amplitude=0.05, racket_period=0.5),
    ModelParams(alpha=0.0, g=9.81, racket_amplitude=0.20, racket_period=0.6),
    ModelParams(alpha=0.8, g=9.81, racket_amplitude=0.60, racket_period=0.92),
    ModelParams(alpha=0.3, g=5.8, racket_amplitude=0.10, racket_period=1.5),
    ModelParams(alpha=0.6, g=9.81, racket_amplitude=0.02, racket_period=0.2),
]


def assert_same(a, b):
    np.testing.assert_array_equal(a.outcome, b.outcome)
    np.testing.assert_array_equal(a.iterations, b.iterations)


@pytest.mark.slow
def test_fig4_grid_same_outcomes_and_impact_counts():
    params = PARAMETERS[0]
    theta, v = np.meshgrid(np.deg2rad(np.linspace(0, 360, 150)), np.linspace(0, 10, 150))
    numpy_result = classify_batch(theta, v, params, kernel="numpy")
    compiled_result = classify_batch(theta, v, params, kernel="compiled")
    assert_same(compiled_result, numpy_result)
    # every outcome of section 3 occurs on this grid, so every branch was compared
    assert set(np.unique(numpy_result.outcome)) == {0, 1, 2}


@pytest.mark.parametrize("params", PARAMETERS)
def test_random_states_same_first_impact_phase_to_the_last_bit(params):
    rng = np.random.default_rng(7)
    theta = rng.uniform(-20.0, 20.0, 4000)  # unwrapped phases too
    racket_v = params.racket_amplitude * params.omega
    v = rng.uniform(-racket_v, 3.0 * racket_v + params.g * params.racket_period, 4000)
    expected = first_impact_phase(theta, v, params.racket_amplitude, params.omega, params.g,
                                  trig=sincos)
    got = compiled.first_impact_phase(theta, v, params, max_steps=2000)
    np.testing.assert_array_equal(got, expected)  # NaN where the ball cannot fly, in both
    assert np.isnan(expected).any() and np.isfinite(expected).any()


@pytest.mark.parametrize("params", PARAMETERS)
def test_random_initial_conditions_same_classification(params):
    rng = np.random.default_rng(11)
    theta = rng.uniform(0.0, 2.0 * np.pi, 3000)
    v = rng.uniform(0.0, 2.0 * params.g * params.racket_period, 3000)
    settings = ClassifySettings(max_iterations=60, tolerance=1e-3, min_hop_s=1e-3)
    fixed = params.cos_theta_fixed() <= 1.0
    numpy_result = classify_batch(theta, v, params, settings, require_fixed_point=fixed,
                                  kernel="numpy")
    compiled_result = classify_batch(theta, v, params, settings, require_fixed_point=fixed,
                                     kernel="compiled")
    assert_same(compiled_result, numpy_result)


def test_edge_cases_grazing_launch_no_flight_unconverged_and_no_fixed_point():
    params = PARAMETERS[2]
    a, w, g = params.racket_amplitude, params.omega, params.g
    theta_graze = math.asin(g / (w * w * a)) + 0.3  # racket decelerates faster than gravity
    theta = np.array([theta_graze, 0.0, 1.0, np.pi, 2.0 * np.pi, -0.0, 7.0])
    v = a * w * np.cos(theta)  # exactly the racket's velocity: grazing / cannot fly
    v[-1] += 1.0
    for max_steps in (1, 2, 3, 2000):  # unconverged solves are NaN in both
        expected = first_impact_phase(theta, v, a, w, g, max_steps=max_steps, trig=sincos)
        got = compiled.first_impact_phase(theta, v, params, max_steps=max_steps)
        np.testing.assert_array_equal(got, expected)
    # no period-1 orbit (amplitude below eq. 8's minimum): NaN target in both kernels
    small = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.01, racket_period=0.92)
    assert small.cos_theta_fixed() > 1.0
    th, vv = np.meshgrid(np.linspace(0, 2 * np.pi, 40), np.linspace(0, 6, 40))
    assert_same(classify_batch(th, vv, small, require_fixed_point=False, kernel="compiled"),
                classify_batch(th, vv, small, require_fixed_point=False, kernel="numpy"))


def test_undecided_points_after_max_iterations_match():
    params = PARAMETERS[3]  # chaotic: many points never settle
    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, 30), np.linspace(0, 8, 30))
    settings = ClassifySettings(max_iterations=5, tolerance=1e-3, min_hop_s=1e-3)
    numpy_result = classify_batch(theta, v, params, settings, require_fixed_point=False,
                                  kernel="numpy")
    assert (numpy_result.outcome == 3).any() and (numpy_result.iterations == 5).any()
    assert_same(classify_batch(theta, v, params, settings, require_fixed_point=False,
                               kernel="compiled"), numpy_result)


def test_the_kernel_s_phase_wrap_is_np_mod_to_the_last_bit():
    """``_wrap`` takes multiples of 2 pi away without fmod's call where that is exact: its
    result must be np.mod's, bit for bit, at the multiples' edges, at -0.0, NaN and inf, and
    on random phases in every branch (a hurried x - 3 * TWO_PI would be off by an ulp)."""
    two_pi = compiled.TWO_PI
    edges = [k * two_pi for k in (-2, -1, 1, 2, 3, 4, 5)]
    special = [0.0, -0.0, 5e-324, -5e-324, 1e-300, -1e-300, np.nan, np.inf, -np.inf,
               *edges, *np.nextafter(edges, np.inf), *np.nextafter(edges, -np.inf)]
    rng = np.random.default_rng(5)
    phases = np.concatenate([special, rng.uniform(-3.0 * two_pi, 9.0 * two_pi, 20_000),
                             rng.uniform(-1e3, 1e3, 2_000)])
    expected = np.mod(phases, two_pi)
    got = np.array([compiled._wrap(x) for x in phases])
    np.testing.assert_array_equal(got.view(np.int64), expected.view(np.int64))


@pytest.mark.parametrize("params", PARAMETERS[:2])
def test_an_impact_s_new_phase_is_np_mod_of_theta_plus_hop(params):
    """``_impact``'s phases after impact (its wrap without fmod, vectorised, and fmod where
    the flight was long or did not converge) against np.mod of the same theta + hop."""
    rng = np.random.default_rng(3)
    m = 3000
    theta = rng.uniform(0.0, 2.0 * np.pi, m)
    racket_v = params.racket_amplitude * params.omega
    v = rng.uniform(-racket_v, 6.0 * params.g * params.racket_period, m)  # hops up to 12 pi
    sin_th, cos_th = sincos(theta)
    c = compiled._constants(params, params.fixed_point(), 1e-3, 1e-3)
    hop, S, D0, C, SN, V, SH, CH = (np.empty(m) for _ in range(8))
    compiled._impact(theta, v, cos_th, sin_th, m, c, 2000, hop, np.empty(m, np.int64),
                     S, D0, C, SN, V, SH, CH)
    long_flight = theta + hop >= 4.0 * compiled.TWO_PI
    assert np.isnan(hop).any() and long_flight.any() and (~long_flight).any()
    np.testing.assert_array_equal(S.view(np.int64),
                                  np.mod(theta + hop, compiled.TWO_PI).view(np.int64))


def test_auto_uses_the_compiled_kernel_unless_turned_off(monkeypatch):
    from bounce_cli.model import native

    calls = []
    original = native.classify_arrays  # the machine code without numba, or numba's dispatcher
    monkeypatch.setattr(native, "classify_arrays",
                        lambda *args: calls.append(1) or original(*args))
    theta, v = np.array([0.5, 1.0]), np.array([5.0, 6.0])
    classify_batch(theta, v, PARAMETERS[0])
    assert calls == [1]
    monkeypatch.setenv("BOUNCE_KERNEL", "numpy")
    assert not classify_module.compiled_kernel_available()
    classify_batch(theta, v, PARAMETERS[0])
    assert calls == [1]


def test_without_numba_the_numpy_kernel_runs(monkeypatch, request):
    from bounce_cli.model import native

    native.numba_installed.cache_clear()  # looked up once per process: again, without it
    request.addfinalizer(native.numba_installed.cache_clear)
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "numba" else real_find_spec(name, *a))
    assert not classify_module.compiled_kernel_available()
    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, 12), np.linspace(0, 10, 12))
    assert_same(classify_grid(theta, v, PARAMETERS[0]),
                classify_batch(theta, v, PARAMETERS[0], kernel="compiled"))


def test_a_compiled_module_that_does_not_import_falls_back_to_numpy(monkeypatch):
    """numba may refuse the kernel's module (no writable cache directory, say): the numpy
    kernel then runs, with the same results (where no machine code was saved before)."""
    import builtins

    from bounce_cli.model import native

    monkeypatch.setattr(native, "classifier", lambda: None)
    classify_module._compiled_module_imports.cache_clear()
    real_import = builtins.__import__

    def refusing(name, globals=None, locals=None, fromlist=(), level=0):
        if level >= 1 and fromlist and "compiled" in fromlist:
            raise RuntimeError("cannot cache function: no locator available")
        return real_import(name, globals, locals, fromlist, level)

    monkeypatch.setattr(builtins, "__import__", refusing)
    try:
        assert not classify_module.compiled_kernel_available()
    finally:
        monkeypatch.setattr(builtins, "__import__", real_import)
        classify_module._compiled_module_imports.cache_clear()
    assert classify_module.compiled_kernel_available()


# -- the controlled map (engine.control.ControlledMap): the same kernel loop over its step ----
@pytest.mark.slow
@pytest.mark.parametrize("params", PARAMETERS[:4], ids=["fig4", "rigid", "dead", "large"])
@pytest.mark.parametrize("gain, rate", [(0.6, 0.9), (0.0, 1.0), (-0.4, 0.5), (1.6, 1.3)])
def test_controlled_map_compiled_is_numpy_point_for_point(params, gain, rate):
    """Random states, and a controller strong enough to ask for periods <= 0 (1.6, 1.3):
    the compiled controlled classification is the numpy one, codes and counts."""
    from bounce_cli.model.control import ControlledMap, PeriodController

    rng = np.random.default_rng(int(1000 * abs(gain)) + 7)
    theta, v = rng.uniform(-1.0, 7.5, 1500), rng.uniform(0.0, 12.0, 1500)
    impact_map = ControlledMap.of(params, PeriodController(gain, rate),  # no fixed point:
                                  require_fixed_point=params.cos_theta_fixed() <= 1.0,
                                  period_tolerance_s=2e-3)  # NaN target, no period1
    settings = ClassifySettings(max_iterations=60)
    numpy_result = classify_module.classify_states(impact_map, theta, v, settings,
                                                   kernel="numpy")
    assert_same(numpy_result, classify_module.classify_states(impact_map, theta, v, settings,
                                                              kernel="compiled"))
    assert len(np.unique(numpy_result.outcome)) >= 2


@pytest.mark.slow
def test_controlled_basin_compiled_in_threads_is_one_process():
    """``classify_grid`` of the controlled map on the compiled kernel in threads (as
    ``bounce basin`` with model.control runs it) and the numpy kernel in this process."""
    from bounce_cli.runtime import parallel
    from bounce_cli.model.control import ControlledMap, PeriodController

    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, 80), np.linspace(0, 10, 80))
    impact_map = ControlledMap.of(PARAMETERS[0], PeriodController(0.7, 0.8),
                                  require_fixed_point=True)
    one = classify_grid(theta, v, impact_map, kernel="numpy")
    with parallel.Threads(2) as threads:
        assert_same(one, classify_grid(theta, v, impact_map, map=threads.map, workers=2,
                                       tile_points=1000, kernel="compiled"))
    # the cycle-switching racket has no compiled kernel: "compiled" runs the numpy loop
    cycle = ControlledMap.of(PARAMETERS[0], PeriodController(0.7, 0.8, switch="cycle"),
                             require_fixed_point=True)
    assert not classify_module.has_compiled_kernel(cycle)
    assert_same(classify_grid(theta, v, cycle, kernel="numpy"),
                classify_grid(theta, v, cycle, kernel="compiled"))


def _in_a_fresh_process(code: str, **env: str) -> str:
    """What ``code`` prints in a new interpreter with ``env`` added (and numba's own
    NUMBA_CPU_* variables removed unless given)."""
    import os
    import subprocess
    import sys

    clean = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU")}
    done = subprocess.run([sys.executable, "-c", code], env={**clean, **env},
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


CPU_FEATURES_AFTER_IMPORT = ("import bounce_cli.model.compiled\n"
                             "from numba.core import config, codegen\n"
                             "print(repr(config.CPU_FEATURES))\n"
                             "print(config.ENABLE_AVX and '+avx512f' in "
                             "codegen.get_host_cpu_features().split(','))")


def test_the_widest_vectors_only_where_numba_s_choice_is_in_force():
    """Importing the kernel lets LLVM use AVX-512's full width on CPUs that have it (numba's
    features and '-prefer-256-bit'), leaves numba alone elsewhere, and never overrides
    a CPU the user named (NUMBA_CPU_NAME: a cache shared by several machines)."""
    features, avx512_in_use = _in_a_fresh_process(CPU_FEATURES_AFTER_IMPORT).splitlines()
    if avx512_in_use == "True":
        assert features.endswith(",-prefer-256-bit'") and "+avx512f" in features
    else:
        assert features == "None"
    named, _ = _in_a_fresh_process(CPU_FEATURES_AFTER_IMPORT,
                                   NUMBA_CPU_NAME="generic").splitlines()
    assert named == "''"  # numba's own default for a generic CPU, untouched


@pytest.mark.slow  # compiles the kernel for a generic CPU: about 10 s
def test_the_vector_width_changes_no_bit(tmp_path):
    """The kernel compiled for a generic x86-64 (no AVX: two doubles a vector at most) gives
    the outcomes, impact counts and first-impact phases of this process's kernel (the
    widest vectors the CPU has), bit for bit: each flight's arithmetic is its own."""
    code = ("import numpy as np, sys\n"
            "from bounce_cli.model import compiled\n"
            "from bounce_cli.model.params import ModelParams\n"
            "p = ModelParams(alpha=0.8, g=9.81, racket_amplitude=0.6, racket_period=0.92)\n"
            "rng = np.random.default_rng(4)\n"
            "th, v = rng.uniform(0, 2 * np.pi, 20000), rng.uniform(0, 10, 20000)\n"
            "o, it = compiled.classify_arrays(th, v, p, p.fixed_point(), 100, 1e-3, 1e-3, 2000)\n"
            "hop = compiled.first_impact_phase(th, v, p, max_steps=2000)\n"
            "sys.stdout.write(o.tobytes().hex() + ' ' + it.tobytes().hex() + ' '"
            " + hop.tobytes().hex())\n")
    generic = _in_a_fresh_process(code, NUMBA_CPU_NAME="generic",
                                  NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    assert _in_a_fresh_process(code) == generic


def test_loading_the_kernel_leaves_scipy_linalg_importable():
    """``compiled.load`` keeps numba's set-up from importing scipy.linalg (start-up time), and
    scipy.linalg imports as usual afterwards; where it is imported already, nothing changes."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from bounce_cli.model import compiled\n"
            "compiled.load()\n"
            "assert 'scipy.linalg' not in sys.modules\n"
            "import scipy.linalg\n"
            "assert scipy.linalg.solve([[2.0]], [4.0])[0] == 2.0\n"
            "with compiled.numba_without_blas():\n"
            "    import scipy.linalg as again\n"
            "assert again is scipy.linalg\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


@pytest.mark.parametrize("params", PARAMETERS)
def test_the_map_s_wrapped_step_with_compiled_hops_is_numpy_s_to_the_last_bit(params):
    # the attractors' iteration (PassiveMap.step, wrapped): 200 impacts of 300 random states,
    # each state's phase, velocity, cos, sin and hop the same bits by either solver; states
    # that cannot fly (NaN hop) are dropped as the callers drop them
    from dataclasses import replace

    from bounce_cli.model.maps import PassiveMap

    rng = np.random.default_rng(5)
    racket_v = params.racket_amplitude * params.omega
    theta = rng.uniform(0.0, 2.0 * np.pi, 300)
    v = rng.uniform(racket_v, 3.0 * racket_v + params.g * params.racket_period, 300)
    plain = PassiveMap.of(params, require_fixed_point=False)
    fast = replace(plain, compiled_hops=True)
    a = plain.start(theta, v, wrap=True)
    b = fast.start(theta, v, wrap=True)
    flown = 0
    for _ in range(200):
        step_a, step_b = plain.step(a, wrap=True), fast.step(b, wrap=True)
        np.testing.assert_array_equal(step_b.hop_phase, step_a.hop_phase)
        for x, y in ((step_a.state.theta, step_b.state.theta), (step_a.state.v, step_b.state.v),
                     *zip(step_a.state.extra, step_b.state.extra)):
            np.testing.assert_array_equal(y, x)
        keep = np.isfinite(step_a.hop_phase)
        flown += int(keep.sum())
        a, b = step_a.state.take(keep), step_b.state.take(keep)
        if a.theta.size == 0:
            break
    assert flown > 300  # the states flew, not only failed to


def test_attractors_label_the_same_with_and_without_the_compiled_hops(monkeypatch):
    # a chaotic point (alpha 0.85, Gamma 1.8: no periodic attractor, long recurrences): the
    # labels and impact counts do not depend on the solver
    from bounce_cli.analysis.attractors import AttractorFinder, RecurrenceSettings
    from bounce_cli.analysis.bifurcation import parameter_point

    params = parameter_point(ModelParams(alpha=0.85, g=9.81, racket_amplitude=0.30,
                                         racket_period=0.92), "gamma", 1.8)
    settings = RecurrenceSettings(transient=200, window=64, max_period=16, sample=20,
                                  recurrence=30, recurrence_impacts=2000, max_impacts=100)
    theta, v = np.meshgrid(np.linspace(0.0, 2.0 * np.pi, 12), np.linspace(0.0, 10.0, 12))
    found = {}
    for kernel in ("auto", "numpy"):
        monkeypatch.setenv("BOUNCE_KERNEL", kernel)
        finder = AttractorFinder(params, settings)
        assert finder.map.compiled_hops == (kernel == "auto")
        finder.discover(theta.ravel()[::7], v.ravel()[::7])
        found[kernel] = (*finder.label(theta, v), [a.kind for a in finder.attractors])
    np.testing.assert_array_equal(found["auto"][0], found["numpy"][0])
    np.testing.assert_array_equal(found["auto"][1], found["numpy"][1])
    assert found["auto"][2] == found["numpy"][2]


@pytest.mark.parametrize("params", PARAMETERS + [
    ModelParams(alpha=0.9, g=9.81, racket_amplitude=0.30, racket_period=0.92)])  # chaotic
def test_the_attractors_recurrence_compiled_is_numpy_s_to_the_last_bit(params):
    # the chaotic orbits' recurrence (analysis.attractors._recurrence): every orbit's visited
    # cells, whether it recurred, and the largest velocity seen, by the numpy loop and by the
    # compiled one; states that cannot fly, cells above and below the velocity range
    from dataclasses import replace

    from bounce_cli.analysis import attractors
    from bounce_cli.model.maps import PassiveMap

    rng = np.random.default_rng(11)
    racket_v = params.racket_amplitude * params.omega
    theta = rng.uniform(-1.0, 8.0, (160, 3))  # unwrapped: the start wraps the last column
    v = rng.uniform(0.5 * racket_v, 3.0 * racket_v + params.g * params.racket_period, (160, 3))
    settings = attractors.RecurrenceSettings(cells_theta=60, cells_v=40, v_range=(0.5, 6.0),
                                             recurrence=30, recurrence_impacts=1000,
                                             window=64, max_period=16)
    plain = PassiveMap.of(params, require_fixed_point=False)
    results = []
    for impact_map in (plain, replace(plain, compiled_hops=True)):
        results.append(attractors._recurrence(settings, attractors.Tessellation.of(settings),
                                              impact_map, theta, v))
    (r_a, vis_a, top_a, stuck_a), (r_b, vis_b, top_b, stuck_b) = results
    np.testing.assert_array_equal(r_b, r_a)
    np.testing.assert_array_equal(vis_b, vis_a)
    np.testing.assert_array_equal(stuck_b, stuck_a)
    assert top_b == top_a
    assert not (r_a & stuck_a).any()
    assert vis_a.sum() > theta.size  # the orbits moved on (beyond their recorded cells)


@pytest.mark.slow
def test_attractors_follow_recurrences_in_threads_to_the_same_result():
    # a chaotic point, the recurrences' chunks followed by two threads at a time (small
    # chunks: many of them): labels, impact counts, attractors as with one after another
    from bounce_cli.analysis import attractors
    from bounce_cli.analysis.attractors import AttractorFinder, RecurrenceSettings
    from bounce_cli.analysis.bifurcation import parameter_point
    from bounce_cli.runtime import parallel

    params = parameter_point(ModelParams(alpha=0.9, g=9.81, racket_amplitude=0.30,
                                         racket_period=0.92), "gamma", 1.6)
    # coarse cells: the chaotic attractor recurs; 5 impacts of labelling: most starts are
    # discovered again
    settings = RecurrenceSettings(transient=200, window=64, max_period=16, sample=40,
                                  recurrence=30, recurrence_impacts=3000, max_impacts=5,
                                  cells_theta=30, cells_v=30, v_range=(0.0, 40.0))
    theta, v = np.meshgrid(np.linspace(0.0, 2.0 * np.pi, 14), np.linspace(0.0, 10.0, 14))
    found = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(attractors, "RECURRENCE_CHUNK", 16)
        for jobs in (1, 2):
            with parallel.executor(jobs, threads=True) as threads:
                finder = AttractorFinder(params, settings)
                finder.discover(theta.ravel()[::5], v.ravel()[::5], follow=threads.map)
                labels, impacts = finder.label(theta, v, follow=threads.map)
            found.append((labels, impacts, [(a.kind, a.cells.tolist()) for a in
                                            finder.attractors], finder.catalogue.v_max_seen,
                          finder.rediscovered))
    np.testing.assert_array_equal(found[1][0], found[0][0])
    np.testing.assert_array_equal(found[1][1], found[0][1])
    assert found[1][2:] == found[0][2:]
    assert found[0][4] > 16  # the labelling left starts to the threads, in several chunks
    assert [kind for kind, _ in found[0][2]] == ["chaotic"] and (found[0][0] == 0).mean() > 0.5
