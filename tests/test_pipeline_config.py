"""Learner params files and checkpoints: what is accepted, what is refused, and how."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from gngdt_core.frame_learner import LEARNER_MODEL_DEFAULTS
from gngdt_io.checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from gngdt_io.profiles import load_profile

REPO_ROOT = Path(__file__).resolve().parents[1]


def test_example_params_file_builds_a_model() -> None:
    from gngdt_core import GNGDT

    config = load_profile(REPO_ROOT / "config" / "learner.toml").config
    assert config.model["lambda_"] == 500
    assert config.options.samples_per_frame == 10000
    GNGDT(**config.model)


def test_params_accept_flat_keys_and_learner_options(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text("max_nodes = 300\nlambda_ = 100\nsamples_per_frame = 777\n")
    config = load_profile(path).config
    assert config.model == {**LEARNER_MODEL_DEFAULTS, "max_nodes": 300, "lambda_": 100}
    assert config.options.samples_per_frame == 777


def test_the_learner_forgets_unless_told_not_to(tmp_path: Path) -> None:
    from gngdt_core import GNGDT

    assert load_profile(None).config.model["utility_k"] == LEARNER_MODEL_DEFAULTS["utility_k"] > 0
    path = tmp_path / "paper.toml"
    path.write_text("[gngdt]\nutility_k = 0   # the paper's GNG-DT: no forgetting\n")
    model = GNGDT(**load_profile(path).config.model)
    assert model.utility_k is None and model.n_forgotten_ == 0


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
    from gngdt_core import GNGDT

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

    from gngdt_io.outputs.rerun_output import add_viewer_arguments

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
