"""YAML configs, --set overrides, one-line errors."""

import textwrap
from pathlib import Path

import pytest

from bounce_cli.runtime.config import (
    MAX_CONFIG_BYTES,
    ConfigError,
    ModelOnlyConfig,
    apply_overrides,
    bundled_config_path,
    load_config,
    parse_override,
    to_yaml,
)


def write(tmp_path, text, name="c.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.mark.parametrize("name, paper_set", [
    ("model", "FIG3_MODEL"), ("trajectory", "FIG3_MODEL"), ("basin", "FIG3_MODEL"),
    ("stability", "FIG3_MODEL"), ("impulse", "FIG3_MODEL"), ("acf", "FIG8_MODEL"),
])
def test_bundled_configs_are_at_the_papers_parameters(name, paper_set):
    """Each bundled config's model block is the paper's parameter set of its figure, as the
    paper module records it (a config edited away from the paper fails here, not in a
    claim)."""
    from bounce_cli.paper import values as paper

    cfg = load_config(ModelOnlyConfig, bundled_config_path(name)) if name == "model" else None
    if cfg is None:
        from bounce_cli.experiments.registry import entry

        cfg = load_config(entry(name).load().schema, bundled_config_path(name))
    assert paper.at_parameters(cfg.params, getattr(paper, paper_set))


def test_old_name_of_the_sticking_threshold_is_still_read(tmp_path):
    from bounce_cli.runtime.config import ClassifyBlock
    from bounce_cli.analysis.classify import ClassifySettings

    old = ClassifyBlock.model_validate({"sticking_interval_s": 0.02})
    assert old.min_hop_s == 0.02 and old.settings().min_hop_s == 0.02
    # defaults are the engine's (section 3's values)
    assert ClassifyBlock().settings() == ClassifySettings()


def test_overrides_parse_as_yaml_scalars():
    assert parse_override("model.alpha=0.4") == (["model", "alpha"], 0.4)
    assert parse_override("a.b=[1, 2]") == (["a", "b"], [1, 2])
    assert parse_override("a=true") == (["a"], True)
    assert parse_override("a=hello") == (["a"], "hello")
    data = apply_overrides({"model": {"alpha": 0.5}}, ["model.alpha=0.3", "model.g=5"])
    assert data == {"model": {"alpha": 0.3, "g": 5}}


@pytest.mark.parametrize("bad", ["model.alpha", "=3", "model..alpha=1", ""])
def test_malformed_override(bad):
    with pytest.raises(ConfigError, match="expected dotted.key=value"):
        parse_override(bad)


def test_override_into_scalar_is_an_error():
    with pytest.raises(ConfigError, match="model.alpha is not a mapping"):
        apply_overrides({"model": {"alpha": 0.5}}, ["model.alpha.x=1"])


@pytest.mark.parametrize(
    "text, expected",
    [
        ("model:\n  alpha: 1.5\n", "model.alpha: Input should be less than 1"),
        ("model:\n  g: -1\n", "model.g: Input should be greater than 0"),
        ("model:\n  alpha: abc\n", "model.alpha: Input should be a valid number"),
        ("model:\n  nope: 1\n", "model.nope: unknown key"),
        ("extra: 1\n", "extra: unknown key"),
        ("model:\n  alpha: .nan\n", "model.alpha: Input should be a finite number"),
        ("model: [1, 2]\n", "model: Input should be a valid dictionary"),
    ],
)
def test_validation_errors_are_one_line_naming_the_key(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(ModelOnlyConfig, path)
    message = str(info.value)
    assert expected in message
    assert "\n" not in message
    assert str(path) in message


def test_override_errors_name_the_override(tmp_path):
    path = write(tmp_path, "model:\n  alpha: 0.5\n")
    with pytest.raises(ConfigError, match=r"^--set: model.alpha: Input should be less than 1"):
        load_config(ModelOnlyConfig, path, ["model.alpha=2"])
    with pytest.raises(ConfigError, match="model.typo: unknown key"):
        load_config(ModelOnlyConfig, path, ["model.typo=2"])


@pytest.mark.parametrize("text", ["model: [1\n", "model:\n  alpha: 0.5\n bad: : :\n", "a: b: c\n"])
def test_malformed_yaml(tmp_path, text):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match="malformed YAML") as info:
        load_config(ModelOnlyConfig, path)
    assert "\n" not in str(info.value)


def test_not_a_mapping_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_config(ModelOnlyConfig, write(tmp_path, "- 1\n- 2\n"))
    with pytest.raises(ConfigError, match="not found"):
        load_config(ModelOnlyConfig, tmp_path / "missing.yaml")


def test_empty_file_gives_defaults_and_resolved_yaml_roundtrips(tmp_path):
    cfg = load_config(ModelOnlyConfig, write(tmp_path, ""))
    again = load_config(ModelOnlyConfig, write(tmp_path, to_yaml(cfg), "again.yaml"))
    assert again == cfg


@pytest.mark.parametrize("command", ["fixed-point", "basin"])
def test_a_config_that_is_not_utf8_is_one_line(tmp_path, cli, user_error, command):
    path = tmp_path / "latin.yaml"
    path.write_bytes(b"model:\n  alpha: 0.5  # r\xe9sum\xe9\n")
    out = tmp_path / "out"
    result = cli(command, "--config", path, *(["--out", out] if command == "basin" else []))
    user_error(result, str(path), "not UTF-8", "0xe9", "save it as UTF-8")
    assert not out.exists()


def test_a_config_larger_than_the_limit_is_refused_before_it_is_read(tmp_path, cli, user_error):
    path = tmp_path / "huge.yaml"
    with open(path, "wb") as handle:
        handle.write(b"model: {}\n")
        handle.truncate(MAX_CONFIG_BYTES + 1)  # sparse: no disk, and all NUL bytes past line 1
    user_error(cli("fixed-point", "--config", path), str(path), "10 MB", "larger than")
    out = tmp_path / "out"
    user_error(cli("basin", "--config", path, "--out", out), "larger than")
    assert not out.exists()


@pytest.mark.slow
def test_a_device_or_a_folder_as_config_is_one_line(tmp_path):
    """``--config /dev/zero`` must not read forever: refused as not a regular file (run in a
    child with bounded memory and time, so that a reader that reads it whole fails fast)."""
    import resource
    import subprocess
    import sys

    def bounded():
        resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))

    for given in ("/dev/zero", str(tmp_path)):
        done = subprocess.run([sys.executable, "-m", "bounce_cli", "fixed-point", "--config",
                               given], capture_output=True, text=True, timeout=120,
                              preexec_fn=bounded)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1, done.stderr[-2000:]
        assert lines[0].startswith(f"bounce: error: {given}: ") and "not a regular file" \
            in lines[0], lines[0]


def test_a_parsed_config_is_cached_by_its_text_and_never_shared(tmp_path):
    """read_yaml keeps parsed configs by their text: a caller that edits its copy does not
    change the next reader's, and an edited file is parsed again."""
    from bounce_cli.runtime.config import read_yaml

    path = write(tmp_path, """\
        model: {alpha: 0.5}
        list: [1, 2]
        """)
    first = read_yaml(path)
    first["model"]["alpha"] = 0.9
    first["list"].append(3)
    assert read_yaml(path) == {"model": {"alpha": 0.5}, "list": [1, 2]}
    path.write_text("model: {alpha: 0.7}\n")
    assert read_yaml(path) == {"model": {"alpha": 0.7}}
