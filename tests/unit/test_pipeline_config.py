"""Learner params files and checkpoints: what is accepted, what is refused, and how."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from gngdt.core.learner.frame_learner import LEARNER_MODEL_DEFAULTS
from gngdt.io.checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from gngdt.io.profiles import load_profile

REPO_ROOT = Path(__file__).resolve().parents[2]


def test_example_params_file_builds_a_model() -> None:
    from gngdt.core import GNGDT

    config = load_profile(REPO_ROOT / "config" / "learner.toml").config
    assert config == load_profile(None).config  # the example only documents: it sets nothing
    assert GNGDT(**config.model).lambda_ == 500
    assert config.options.samples_per_frame == 10000


def test_params_accept_flat_keys_and_learner_options(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text("max_nodes = 300\nlambda_ = 100\nsamples_per_frame = 777\n")
    config = load_profile(path).config
    assert config.model == {**LEARNER_MODEL_DEFAULTS, "max_nodes": 300, "lambda_": 100}
    assert config.options.samples_per_frame == 777


def test_the_learner_forgets_unless_told_not_to(tmp_path: Path) -> None:
    from gngdt.core import GNGDT

    assert load_profile(None).config.model["utility_k"] == LEARNER_MODEL_DEFAULTS["utility_k"] > 0
    path = tmp_path / "paper.toml"
    path.write_text("[gngdt]\nutility_k = 0   # the paper's GNG-DT: no forgetting\n")
    model = GNGDT(**load_profile(path).config.model)
    assert model.check_params()["utility_k"] is None and model.n_forgotten_ == 0


def test_unknown_params_key_is_named(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text("[gngdt]\nmax_nodez = 10\n")
    with pytest.raises(ValueError, match=r"unknown key 'max_nodez'"):
        load_profile(path)


def test_invalid_toml_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("max_nodes = = 3\n")
    with pytest.raises(ValueError, match=r"broken\.toml"):
        load_profile(path)


def test_checkpoint_round_trip_and_model_resume(tmp_path: Path) -> None:
    from gngdt.core import GNGDT

    rng = np.random.default_rng(3)
    positions = rng.random((3000, 3), dtype=np.float32)
    colors = rng.integers(0, 256, (3000, 3), dtype=np.uint8)
    model = GNGDT(random_state=0).partial_fit(positions, colors, n_steps=3000)
    path = tmp_path / "ckpt.npz"
    save_checkpoint(path, model.get_state(), {"camera": "camera"})
    state, metadata = load_checkpoint(path)
    assert metadata["camera"] == "camera"
    resumed = GNGDT.from_state(state)
    assert resumed.n_nodes_ == model.n_nodes_ > 2
    np.testing.assert_array_equal(resumed.positions_, model.positions_)
    assert not list(tmp_path.glob(".*tmp"))  # the temporary file was renamed away


def test_tampered_checkpoint_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.npz"
    save_checkpoint(path, {"weights": np.arange(10, dtype=np.float32)})
    with np.load(path, allow_pickle=False) as archive:
        arrays = {key: archive[key] for key in archive.files}
    arrays["state/weights"][3] = 99.0
    np.savez(path, **arrays)
    with pytest.raises(CheckpointError, match="sha256"):
        load_checkpoint(path)


def test_truncated_or_foreign_checkpoint_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.npz"
    save_checkpoint(path, {"weights": np.arange(1000, dtype=np.float32)})
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(CheckpointError, match=r"ckpt\.npz"):
        load_checkpoint(path)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, something=np.zeros(3))
    with pytest.raises(CheckpointError, match="not a gngdt checkpoint"):
        load_checkpoint(foreign)
    pickled = tmp_path / "pickled.npz"
    with zipfile.ZipFile(pickled, "w") as archive:
        archive.writestr("metadata.npy", json.dumps({"x": 1}))
    with pytest.raises(CheckpointError):
        load_checkpoint(pickled)


def test_logger_viewer_options_are_reruns_own() -> None:
    import argparse

    import rerun as rr

    from gngdt.io.outputs.rerun_output import add_viewer_arguments

    ours, theirs = argparse.ArgumentParser(), argparse.ArgumentParser()
    add_viewer_arguments(ours)
    rr.script_add_args(theirs)

    def options(parser: argparse.ArgumentParser) -> list[tuple]:
        return sorted((tuple(a.option_strings), a.dest, a.default, a.nargs, a.help)
                      for a in parser._actions if a.dest != "help")

    # but --headless: the logger never opens a GUI, so "don't show GUI" would mean nothing
    assert options(ours) == [option for option in options(theirs)
                             if option[0] != ("--headless",)]
    with pytest.raises(SystemExit):
        ours.parse_args(["--headless"])


def test_the_example_params_file_documents_every_key_with_its_default() -> None:
    """config/learner.toml shows every key with the value used when no file sets it (commented
    out: a file only overrides), so the documentation cannot drift from the declarations."""
    import re
    import tomllib

    from gngdt.io.profiles import load_profile, model_parameter_names

    text = (REPO_ROOT / "config" / "learner.toml").read_text()
    documented = {}
    for match in re.finditer(r"^# ([a-z_0-9]+) = ([^#\n]+?)\s*(?:#.*)?$", text, re.MULTILINE):
        documented[match.group(1)] = tomllib.loads(f"v = {match.group(2)}")["v"]
    mentioned = set(re.findall(r"^# ([a-z_0-9]+)\b", text, re.MULTILINE))
    config = load_profile(None).config
    defaults = {**{("lambda" if k == "lambda_" else k): v for k, v in config.model.items()},
                **vars(config.options)}
    import inspect

    from gngdt.core import GNGDT

    for name, parameter in inspect.signature(GNGDT.__init__).parameters.items():
        if name in model_parameter_names():
            defaults.setdefault("lambda" if name == "lambda_" else name, parameter.default)
    assert mentioned >= set(defaults), f"undocumented: {sorted(set(defaults) - mentioned)}"
    for name, value in documented.items():
        expected = defaults[name]
        expected = list(expected) if isinstance(expected, tuple) else expected
        assert value == expected, f"{name}: documented {value!r}, used {expected!r}"


def test_print_params_names_where_every_value_comes_from(tmp_path: Path, capsys) -> None:
    from gngdt.services.cli import main as gngdt_main

    params = tmp_path / "p.toml"
    params.write_text("[gngdt]\nmax_nodes = 300\n[learner]\nseed = 4\n")
    assert gngdt_main(["learn", "--params", str(params), "--samples-per-frame", "777",
                       "--print-params"]) == 0
    printed = capsys.readouterr().out
    lines = {line.split("=")[0].strip(): line for line in printed.splitlines() if "=" in line}
    assert lines["max_nodes"].endswith(f"# {params}")
    assert lines["seed"].endswith(f"# {params}")
    assert "777" in lines["samples_per_frame"] and lines["samples_per_frame"].endswith(
        "# command line")
    assert lines["replay_share"].endswith("# the learner's default")  # declared once, in core
    assert lines["eta1"].startswith("eta1 = 0.025") and lines["eta1"].endswith("# default")


def test_a_profile_setting_the_steps_per_frame_twice_differently_is_refused(tmp_path: Path):
    path = tmp_path / "twice.toml"
    path.write_text("[learner]\nsamples_per_frame = 5000\n[frames]\nsteps_per_frame = 4000\n")
    with pytest.raises(ValueError, match="contradicts samples_per_frame = 5000"):
        load_profile(path)
    path.write_text("[frames]\nsteps_per_frame = 4000\n")  # the other name alone: the same key
    config = load_profile(path).config
    assert config.options.samples_per_frame == config.schedule.steps_per_frame == 4000
