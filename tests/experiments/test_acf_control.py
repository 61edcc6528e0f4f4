"""``bounce acf`` with ``model.control`` (racket period control, ``engine.control``): the
VAR(1) theory with the 3 x 3 Jacobian against runs of the controlled stochastic map; gain 0
is the passive run byte for byte."""

import numpy as np
import pytest

from bounce_cli.runtime.config import ConfigError, bundled_config_path, load_config
from bounce_cli.experiments import acf
from bounce_cli.experiments.base import RunOptions

SMALL = ["long_runs.runs=20", "long_runs.bounces=1000", "trials.repetitions=3"]


def run(overrides):
    config = load_config(acf.AcfConfig, bundled_config_path("acf"), SMALL + overrides)
    return config, acf.run(config, RunOptions())


@pytest.mark.slow
def test_gain_zero_is_the_passive_run_byte_for_byte():
    _, passive = run([])
    config, zero = run(["model.control.gain=0", "model.control.rate=0.5"])
    for name, frame in passive.frames.items():
        assert frame.to_csv(index=False) == zero.frames[name].to_csv(index=False), name
    # a passive config dumps without a control key (run.json unchanged)
    assert "control" not in load_config(acf.AcfConfig, bundled_config_path("acf")).model_dump(
        mode="json")["model"]


def test_controlled_theory_matches_the_controlled_map():
    """K = 0.7, c = 1 at Fig. 8's parameters: eq. 19 with the 3 x 3 Jacobian and the map's
    noise covariance against 20 runs of 1000 bounces of the controlled map (lags 1-3, within
    4 SE + 0.01: the map is nonlinear at this noise, see bounce acf)."""
    _, result = run(["model.control.gain=0.7", "model.control.rate=1.0"])
    frame = result.frames["acf.csv"]
    near = frame[frame.lag.between(1, 3)]
    assert (np.abs(near.sample_mean - near.theory_map) <= 4 * near.sample_se + 0.01).all()
    # control shows: the phase becomes persistent (bounce control's numbers at Fig. 8's model)
    lag1 = frame[frame.lag == 1].set_index("pair")
    assert lag1.loc["theta_theta", "theory_map"] == pytest.approx(0.58, abs=0.01)
    assert lag1.loc["v_to_theta", "theory_map"] == pytest.approx(-0.06, abs=0.01)


def test_control_refuses_the_phi_reading_and_an_unstable_controller():
    with pytest.raises(ConfigError, match="velocity_phase"):
        run(["model.control.gain=0.7", "noise.velocity_phase=phi"])
    with pytest.raises(Exception, match="unstable"):
        run(["model.control.gain=1.4", "model.control.rate=1.0"])
