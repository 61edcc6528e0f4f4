"""`bounce sweep`: the same sweep.csv for --jobs 1, --jobs 2 and a Dask LocalCluster; a 1-D
sweep across eq. 8's existence threshold; an interrupted sweep resumed to the same result
without recomputing its finished points, and refused into another config; user errors."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bounce_cli.runtime import checkpoints
from bounce_cli.model.params import ModelParams
from bounce_cli.experiments import sweep as sweep_experiment
from bounce_cli.runtime.interrupts import Interrupted

SMALL = ("--set", "sweep.x.num=3", "--set", "sweep.y.num=2",
         "--set", "basin.theta0_deg.num=10", "--set", "basin.v0_m_s.num=10",
         "--set", "classify.max_iterations=30")
#: the uncertainty exponent too (random initial conditions: one stream per point)
UNCERTAINTY = ("--set", "measures.uncertainty=true", "--set", "measures.samples=40",
               "--set", "measures.eps=[0.01, 0.1]")


def run_sweep(cli, out: Path, *extra):
    result = cli("sweep", "--quiet", "--out", out, *SMALL, *extra)
    return result


@pytest.mark.slow
def test_every_backend_writes_the_same_sweep(cli, tmp_path):
    distributed = pytest.importorskip("distributed")
    one = run_sweep(cli, tmp_path / "one", *UNCERTAINTY, "--jobs", "1")
    assert one.exit_code == 0, one.output
    two = run_sweep(cli, tmp_path / "two", *UNCERTAINTY, "--jobs", "2")
    assert two.exit_code == 0, two.output
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        dask = run_sweep(cli, tmp_path / "dask", *UNCERTAINTY,
                         "--scheduler", cluster.scheduler_address)
    assert dask.exit_code == 0, dask.output
    for name in ("sweep.csv", "axes.csv", "uncertainty.csv"):
        reference = (tmp_path / "one" / name).read_bytes()
        assert (tmp_path / "two" / name).read_bytes() == reference, name
        assert (tmp_path / "dask" / name).read_bytes() == reference, name
    frame = pd.read_csv(tmp_path / "one" / "sweep.csv")
    assert len(frame) == 6 and list(frame.point) == list(range(6))
    assert frame.ix.tolist() == [0, 1, 2, 0, 1, 2] and frame.iy.tolist() == [0, 0, 0, 1, 1, 1]
    # the grid of the config: alpha along x, AC along y (a_r set by section 4's formula)
    assert np.allclose(frame.alpha, np.tile(np.linspace(0.3, 0.8, 3), 2))
    assert np.allclose(frame.ac_g, np.repeat([-1.6, -0.1], 3), rtol=1e-9)
    assert frame.uncertainty_exponent.notna().any()
    assert not (tmp_path / "one" / "points").exists()  # committed: the points are in the CSV
    assert json.loads((tmp_path / "one" / "run.json").read_text())["seed"] == 1


def test_a_line_across_the_existence_threshold(cli, tmp_path, paper_params):
    """racket_amplitude 0.1 .. 0.3 m at the paper's alpha, tau: the period-1 orbit exists from
    a_r = pi (1-alpha)/(1+alpha) g / w^2 (eq. 8) on; below it, NaN fixed-point columns and
    no period-1 initial condition."""
    out = tmp_path / "line"
    result = cli("sweep", "--quiet", "--out", out, "--jobs", "1",
                 "--set", "sweep.y=null", "--set", "sweep.x.parameter=racket_amplitude",
                 "--set", "sweep.x.start=0.1", "--set", "sweep.x.stop=0.3",
                 "--set", "sweep.x.num=5", "--set", "basin.theta0_deg.num=20",
                 "--set", "basin.v0_m_s.num=20")
    assert result.exit_code == 0, result.output
    frame = pd.read_csv(out / "sweep.csv")
    assert "iy" not in frame and len(frame) == 5
    threshold = paper_params.min_racket_amplitude()
    assert 0.2 < threshold < 0.25
    below = frame.racket_amplitude_m < threshold
    assert below.tolist() == [True, True, True, False, False]
    assert frame.loc[below, ["fixed_point_v_m_s", "spectral_radius", "ac_g"]].isna().all().all()
    assert (frame.loc[below, "fraction_period1"] == 0).all()
    assert (frame.loc[~below, "fraction_period1"] > 0).all()
    fractions = frame[[c for c in frame if c.startswith("fraction_")]].sum(axis=1)
    assert np.allclose(fractions, 1.0)
    at_paper = frame.loc[frame.racket_amplitude_m == 0.3].iloc[0]
    assert at_paper.spectral_radius == pytest.approx(0.5, abs=1e-3)  # eq. 10 at Fig. 4
    assert (out / "sweep.png").is_file() and "uncertainty.csv" not in result.output
    # the figure is redrawn from the CSVs alone
    frames = {p.name: pd.read_csv(p) for p in out.glob("*.csv")}
    assert set(sweep_experiment.draw(frames)) == {"sweep.png"}


@pytest.mark.slow
def test_an_interrupted_sweep_resumes_to_the_same_result(cli, tmp_path, monkeypatch, user_error):
    reference = tmp_path / "reference"
    assert run_sweep(cli, reference, "--jobs", "1").exit_code == 0

    out = tmp_path / "resumed"
    save = checkpoints.PointFolder.save
    saved = []

    def save_then_stop(self, index, result):
        save(self, index, result)
        saved.append(index)
        if len(saved) == 2:
            raise Interrupted(2)  # as SIGINT arriving after the second point

    monkeypatch.setattr(checkpoints.PointFolder, "save", save_then_stop)
    stopped = run_sweep(cli, out, "--jobs", "1")
    assert stopped.exit_code == 130 and "bounce: interrupted" in stopped.stderr
    # the one line says where the finished points are and how to go on
    assert (f"bounce: interrupted (2 finished tasks kept in {out / 'points'}/: --resume "
            "continues)") in " ".join(stopped.stderr.split())
    monkeypatch.setattr(checkpoints.PointFolder, "save", save)
    kept = sorted(p.name for p in (out / "points").glob("point-*.json"))
    assert kept == ["point-000000.json", "point-000001.json"]
    assert not (out / "sweep.csv").exists() and not list(out.glob(".*tmp"))

    # without --resume the finished points are not thrown away silently
    user_error(run_sweep(cli, out, "--jobs", "1"), "--resume", "2 finished points")
    # a changed config does not resume into them
    user_error(run_sweep(cli, out, "--jobs", "1", "--resume", "--set", "seed=2"),
               "--resume", "different config", "seed")
    assert len(list((out / "points").glob("point-*.json"))) == 2

    evaluated = []
    evaluate = sweep_experiment.evaluate_point

    def counting(task):
        evaluated.append(task.index)
        return evaluate(task)

    monkeypatch.setattr(sweep_experiment, "evaluate_point", counting)
    resumed = cli("sweep", "--out", out, *SMALL, "--jobs", "1", "--resume")
    assert resumed.exit_code == 0, resumed.output
    assert evaluated == [2, 3, 4, 5]
    assert "2 resumed from an interrupted run" in " ".join(resumed.stderr.split())
    for name in ("sweep.csv", "axes.csv", "run.json"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    assert not (out / "points").exists()


@pytest.mark.slow
def test_force_starts_over_and_resume_without_points_just_runs(cli, tmp_path):
    out = tmp_path / "o"
    folder = checkpoints.PointFolder(out, {"command": "sweep", "config": {"old": 1}},
                                     resume=False, force=False)
    folder.save(0, {"index": 0, "row": {}, "uncertainty": None})
    assert run_sweep(cli, out, "--jobs", "1", "--force").exit_code == 0
    assert not (out / "points").exists()
    fresh = tmp_path / "fresh"
    assert run_sweep(cli, fresh, "--jobs", "1", "--resume").exit_code == 0
    assert (fresh / "sweep.csv").read_bytes() == (out / "sweep.csv").read_bytes()


def test_a_resumed_point_file_holds_the_exact_numbers(tmp_path):
    folder = checkpoints.PointFolder(tmp_path, {"command": "sweep", "config": {}},
                                     resume=False, force=False)
    row = {"x": 0.1 + 0.2, "y": math.nan, "z": 1e-300, "n": 7}
    folder.save(3, {"index": 3, "row": row, "uncertainty": None})
    again = checkpoints.PointFolder(tmp_path, {"command": "sweep", "config": {}},
                                    resume=True, force=False).load()[3]["row"]
    assert again["x"] == 0.1 + 0.2 and math.isnan(again["y"]) and again["z"] == 1e-300
    assert again["n"] == 7 and isinstance(again["n"], int)


@pytest.mark.parametrize("settings, needle", [
    (("sweep.y.start=0.1", "sweep.y.stop=0.5"), "ac_g must be <= 0"),
    (("sweep.y.parameter=alpha",), "different parameters"),
    (("sweep.x.parameter=racket_amplitude",), "sweep one of them"),
    (("sweep.x.stop=1.2",), "alpha"),
    (("basin.v0_m_s.num=3",), "entropy_box"),
    (("sweep.x.parameter=gamma",), "sweep.x.parameter"),
    (("limits.max_basin_points=100",), "limits.max_basin_points"),
])
def test_user_errors_are_one_line(cli, user_error, tmp_path, settings, needle):
    args = [a for s in settings for a in ("--set", s)]
    user_error(cli("sweep", "--quiet", "--out", tmp_path / "o", *args), needle)
    assert not (tmp_path / "o").exists()


def test_an_unreachable_scheduler_is_one_line(cli, user_error, tmp_path):
    pytest.importorskip("distributed")
    result = cli("sweep", "--quiet", "--out", tmp_path / "o", *SMALL,
                 "--scheduler", "tcp://127.0.0.1:9")
    user_error(result, "--scheduler tcp://127.0.0.1:9", "cannot connect")
    assert not (tmp_path / "o").exists()


class NotAScheduler:
    """A TCP service on a free local port that is not a Dask scheduler: ``silent`` accepts
    connections and never answers; ``http`` answers every request with an HTTP 400."""

    def __init__(self, kind: str) -> None:
        import socket
        import threading

        self.kind = kind
        self.server = socket.socket()
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(8)
        self.address = f"tcp://127.0.0.1:{self.server.getsockname()[1]}"
        self.held: list = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            self.held.append(conn)
            if self.kind == "http":
                try:
                    conn.recv(65536)
                    conn.sendall(b"HTTP/1.0 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
                except OSError:
                    pass

    def close(self) -> None:
        self.server.close()
        for conn in self.held:
            conn.close()


@pytest.fixture
def not_a_scheduler(request):
    service = NotAScheduler(request.param)
    yield service
    service.close()


@pytest.mark.parametrize("not_a_scheduler, needle", [
    ("silent", "no answer as a Dask scheduler within 1.5 s"),
    ("http", "a service answers there, but not as a Dask scheduler"),
], indirect=["not_a_scheduler"], ids=["silent", "http"])
@pytest.mark.slow
def test_a_service_that_is_not_a_scheduler_is_one_line(cli, user_error, tmp_path, monkeypatch,
                                                       not_a_scheduler, needle):
    """A port that accepts connections but is not Dask: a silent one kept the client waiting
    for minutes (its timeout did not apply) with signals held; an HTTP server's reply, read
    as a frame length, asked numpy for 3 EiB (a traceback)."""
    pytest.importorskip("distributed")
    from bounce_cli.runtime import parallel

    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 1.0)
    monkeypatch.setattr(parallel, "CONNECT_GRACE_S", 0.5)
    started = time.monotonic()
    result = cli("sweep", "--quiet", "--out", tmp_path / "o", *SMALL,
                 "--scheduler", not_a_scheduler.address)
    user_error(result, f"--scheduler {not_a_scheduler.address}", "cannot connect", needle)
    assert time.monotonic() - started < 10
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.parametrize("not_a_scheduler", ["silent"], indirect=True)
def test_ctrl_c_while_waiting_for_a_silent_scheduler(tmp_path, not_a_scheduler):
    pytest.importorskip("distributed")
    out = tmp_path / "o"
    proc = subprocess.Popen(
        [sys.executable, "-m", "bounce_cli", "sweep", "--quiet", "--out", str(out), *SMALL,
         "--scheduler", not_a_scheduler.address],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 30
    while len(not_a_scheduler.held) < 2 and time.monotonic() < deadline:  # probe, then client
        time.sleep(0.05)
    assert len(not_a_scheduler.held) >= 2, "the client never connected"
    time.sleep(0.3)
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=10)
    assert time.monotonic() - sent < 2.0
    assert proc.returncode == 130, err
    assert err.strip() == "bounce: interrupted"
    assert not out.exists()


def test_only_sweep_takes_resume_and_scheduler(cli):
    assert "--resume" in cli("sweep", "--help").stdout
    assert "--scheduler" in cli("sweep", "--help").stdout
    basin_help = cli("basin", "--help").stdout
    assert "--resume" not in basin_help and "--scheduler" not in basin_help


def test_the_bundled_sweep_runs_in_the_library_without_files(paper_params):
    from bounce_cli.runtime.config import bundled_config_path, load_config
    from bounce_cli.experiments.base import RunOptions

    config = load_config(sweep_experiment.SweepConfig, bundled_config_path("sweep"),
                         ["sweep.x.num=2", "sweep.y.num=2", "basin.theta0_deg.num=5",
                          "basin.v0_m_s.num=5"])
    result = sweep_experiment.run(config, RunOptions())
    assert len(result.frames["sweep.csv"]) == 4
    assert isinstance(config.params, ModelParams)


@pytest.mark.slow  # about 10 s: three sweeps, two of them in their own processes
@pytest.mark.skipif(not hasattr(signal, "SIGINT") or sys.platform == "win32",
                    reason="POSIX signals")
def test_a_real_ctrl_c_mid_sweep_then_resume(cli, tmp_path, ended, dumpable_env):
    """``bounce sweep --jobs 2`` in its own process, SIGINT to its process group (a terminal's
    Ctrl-C) once a point is on disk: exit 130, the finished points kept; ``--resume`` then
    writes the sweep.csv of an uninterrupted run."""
    grid = ("--set", "sweep.x.num=6", "--set", "sweep.y.num=4",
            "--set", "basin.theta0_deg.num=40", "--set", "basin.v0_m_s.num=40")
    out = tmp_path / "run"
    command = [sys.executable, "-m", "bounce_cli", "sweep", "--quiet", "--jobs", "2",
               "--out", str(out), *grid]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True,
                               start_new_session=True, env=dumpable_env)
    deadline = time.monotonic() + 60
    while not list((out / "points").glob("point-*.json")) and process.poll() is None:
        assert time.monotonic() < deadline, "no point finished within a minute"
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = ended(process, 30, "bounce sweep after SIGINT")
    assert process.returncode == 130, stderr
    kept = len(list((out / "points").glob("point-*.json")))
    # one line, saying where the finished points are and how to go on
    assert " ".join(stderr.split()) == (
        f"bounce: interrupted ({kept} finished task{'s' if kept != 1 else ''} kept in "
        f"{out / 'points'}/: --resume continues)")
    assert 1 <= kept < 24 and not (out / "sweep.csv").exists()

    resumed = subprocess.run([*command, "--resume"], capture_output=True, text=True,
                             timeout=120)
    assert resumed.returncode == 0, resumed.stderr
    reference = cli("sweep", "--quiet", "--jobs", "1", "--out", tmp_path / "reference", *grid)
    assert reference.exit_code == 0, reference.output
    assert (out / "sweep.csv").read_bytes() == (tmp_path / "reference" / "sweep.csv").read_bytes()
    assert not (out / "points").exists()


RESULTS = Path(__file__).resolve().parents[2] / "results"


def test_the_committed_atlas_agrees_with_eq14_and_with_the_bifurcation_diagram():
    """results/sweep (bundled alpha x AC): stable exactly where eq. 14 says (the radius from
    the Jacobian of eq. 9 at each point, the boundary from its closed form), and at alpha 0.5,
    AC -1.6 g (Gamma 1.91) the basin all but sticks, as results/bifurcation's orbits do there
    (2000 impacts each, an independent route to the attractor)."""
    from bounce_cli.model.linear import flip_boundary_g

    atlas = pd.read_csv(RESULTS / "sweep" / "sweep.csv")
    stable = atlas.spectral_radius < 1
    assert stable.equals(atlas.ac_g > flip_boundary_g(atlas.alpha))
    assert 0 < stable.sum() < len(atlas)
    assert (atlas.loc[~stable, "fraction_period1"] < 0.01).all()
    assert (atlas.loc[stable & (atlas.ac_g < -0.5), "fraction_period1"] > 0.2).all()
    point = atlas[(atlas.alpha == 0.5) & np.isclose(atlas.ac_g, -1.6)].iloc[0]
    attractors = pd.read_csv(RESULTS / "bifurcation" / "attractors.csv")
    nearest = attractors.gamma.iloc[(attractors.gamma - point.gamma).abs().argmin()]
    assert abs(nearest - point.gamma) < 0.005
    assert set(attractors.loc[attractors.gamma == nearest, "attractor"]) == {"sticking"}
    assert point.fraction_sticking > 0.85 and point.fraction_undecided < 0.01


def test_a_sweep_too_large_is_refused_before_any_point_is_made(cli, user_error, monkeypatch,
                                                                tmp_path):
    """10^8 parameter points took minutes and gigabytes to build before the refusal."""
    def never(config):
        raise AssertionError("the parameter grid was built")

    monkeypatch.setattr(sweep_experiment, "parameter_grid", never)
    user_error(cli("sweep", "--set", "sweep.x.num=10000", "--set", "sweep.y.num=10000",
                   "--out", tmp_path / "sweep"),
               "limits.max_basin_points", "100,000,000 parameter points")
    assert not (tmp_path / "sweep").exists()
