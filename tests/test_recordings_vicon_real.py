"""A real Vicon Nexus CSV export (an excerpt of the pyomeca project's test file, Apache 2.0;
see tests/data/vicon/README.md): read by label, in its own units, with its frame rate."""

from pathlib import Path

import numpy as np
import pandas as pd

from bounce_cli.runtime.config import bundled_config_path, load_config
from bounce_cli.experiments.extract import ExtractConfig
from bounce_cli.data.recordings import read_recording

EXPORT = Path(__file__).parent / "data" / "vicon" / "pyomeca_markers_excerpt.csv"


def read(*overrides):
    cfg = load_config(ExtractConfig, bundled_config_path("extract"), list(overrides))
    warnings = []
    trials = read_recording(EXPORT, cfg.columns, cfg.units, cfg.markers, cfg.csv, cfg.format,
                            warnings.append)
    return trials, warnings


def test_a_real_vicon_export_is_read_by_label_in_metres():
    """Two racket markers averaged, a third as the ball, z vertical, mm -> m, 100 Hz: each
    against the file's own columns read independently with pandas."""
    trials, warnings = read("markers.racket=[boite:gauche_ext, boite:droite_ext]",
                            "markers.ball=Daphnee:ASISr")
    assert len(trials) == 1 and not warnings
    raw = pd.read_csv(EXPORT, skiprows=5, header=None)
    names = pd.read_csv(EXPORT, skiprows=2, nrows=1, header=None).iloc[0]
    column = {name: i for i, name in names.items() if isinstance(name, str)}
    z = {name: raw[i + 2].to_numpy(float) / 1000.0 for name, i in column.items()}
    trial = trials[0]
    assert len(trial.t) == 60
    np.testing.assert_allclose(trial.t, (raw[0].to_numpy(float) - 1) / 100.0, atol=1e-12)
    np.testing.assert_allclose(trial.racket, (z["boite:gauche_ext"] + z["boite:droite_ext"]) / 2,
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(trial.ball, z["Daphnee:ASISr"], rtol=0, atol=1e-9)


def test_a_label_the_export_lacks_is_named():
    import pytest

    from bounce_cli.runtime.config import ConfigError

    with pytest.raises(ConfigError) as info:
        read("markers.racket=paddle", "markers.ball=Daphnee:ASISr")
    assert "paddle" in str(info.value)


def test_the_former_c3d_block_is_still_read_as_markers():
    """Configs written before the markers block (c3d: racket_marker, ball_marker) still load."""
    import pytest

    from bounce_cli.runtime.config import ConfigError

    old = load_config(ExtractConfig, bundled_config_path("extract"),
                      ["c3d.racket_marker=paddle", "c3d.ball_marker=b", "c3d.vertical_axis=y"])
    assert (old.markers.racket, old.markers.ball, old.markers.vertical_axis) == ("paddle", "b",
                                                                                 "y")
    both = load_config(ExtractConfig, bundled_config_path("extract"),
                       ["c3d.racket_marker=paddle", "markers.ball=b"])
    assert (both.markers.racket, both.markers.ball) == ("paddle", "b")
    with pytest.raises(ConfigError, match="markers.marker: unknown key"):
        load_config(ExtractConfig, bundled_config_path("extract"), ["c3d.marker=x"])
