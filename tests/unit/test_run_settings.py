"""Each service's options are declared once (its option groups) and reach it through `gngdt
run`: run has them, and hands each service its values in a settings file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from gngdt.services import learner
from gngdt.services.cli import build_parser
from gngdt.services.plumbing.settings import (
    OptionGroup,
    apply_settings,
    read_settings,
    write_settings,
)
from gngdt.services.run import child_settings


@pytest.fixture
def toy_learner_option() -> Iterator[None]:
    """The learner's option group with one more option, ``--toy-option PATH``, for one test
    (run's option groups are the services' own lists)."""
    declared = learner.SETTINGS[0]

    def with_a_toy_option(group: object) -> None:
        declared.declare(group)
        group.add_argument("--toy-option", type=Path, metavar="PATH")

    learner.SETTINGS[0] = OptionGroup(declared.title, with_a_toy_option)
    try:
        yield
    finally:
        learner.SETTINGS[0] = declared


def test_a_learner_option_declared_once_reaches_the_learner_through_run(
        tmp_path: Path, toy_learner_option: None) -> None:
    args = build_parser().parse_args(["run", "recording.mcap", "--toy-option", "/data/toy",
                                      "--samples-per-frame", "1234"])
    settings = child_settings(args, "learn")
    assert settings["toy_option"] == Path("/data/toy") and settings["samples_per_frame"] == 1234
    path = write_settings(tmp_path / "learn.settings.json", settings)
    assert path.stat().st_mode & 0o777 == 0o600
    child = build_parser().parse_args(["learn", "--settings", str(path)])
    assert child.toy_option is None  # not on the learner's command line: from the file
    apply_settings(child, learner.SETTINGS)
    assert child.toy_option == Path("/data/toy") and child.samples_per_frame == 1234


def test_run_decides_capture_s_point_cap_and_poses_under_track(tmp_path: Path) -> None:
    parse = build_parser().parse_args
    plain = child_settings(parse(["run", "recording.mcap"]), "capture", veil_ratio=0.03)
    assert plain["max_points"] == 50_000 and plain["fixed_frame"] == "auto"
    assert plain["drop_veil"] == 0.03
    tracked = child_settings(parse(["run", "recording.mcap", "--track", "--voxel", "0.01"]),
                             "capture")
    assert tracked["max_points"] == 0 and tracked["fixed_frame"] == "none"
    assert tracked["voxel"] == 0.01
    chosen = child_settings(parse(["run", "recording.mcap", "--max-points", "7"]), "capture")
    assert chosen["max_points"] == 7


def test_a_settings_file_that_is_not_one_is_refused(tmp_path: Path) -> None:
    args = build_parser().parse_args(["learn", "--settings", str(tmp_path / "absent.json")])
    with pytest.raises(ValueError, match=r"absent\.json"):
        apply_settings(args, learner.SETTINGS)
    wrong = write_settings(tmp_path / "wrong.json", {"no_such_option": 1})
    args.settings = wrong
    with pytest.raises(ValueError, match="no_such_option"):
        apply_settings(args, learner.SETTINGS)
    (tmp_path / "list.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match="not a JSON object"):
        read_settings(tmp_path / "list.json")
