"""What `gngdt record images` checks while importing (issue 24.1, 24.5, 24.6): the depth range it
found, float or implausible depth, each posed frame against its depth with the likely cause of
misread poses, and odd files (a stamp of Infinity, a pose file beyond its limit, NaN camera
parameters) refused with the file named, never a traceback."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.image_folders import run_cli

from gngdt.core.sensor.geometry import matrix_to_pose
from gngdt.io import pose_files
from gngdt.io.errors import RecordingError
from gngdt.io.images import iter_image_frames, load_camera
from gngdt.io.mcap.reader import read_frames


@pytest.fixture(scope="module")
def walk_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """24 frames of the virtual walk (160x120) as a redwood folder, with camera.json and the
    true camera-to-world poses in ``poses.txt`` (tx ty tz qx qy qz qw per line) and the same
    poses written w x y z in ``poses_wxyz.txt``."""
    from gngdt.io.synth.render import render_scene

    folder = tmp_path_factory.mktemp("walk")
    (folder / "color").mkdir()
    (folder / "depth").mkdir()
    right, w_first = [], []
    for index, frame in enumerate(render_scene("tabletop_walk", 24, width=160, height=120)):
        cv2.imwrite(str(folder / "color" / f"{index:06d}.png"), frame.color[..., ::-1])
        cv2.imwrite(str(folder / "depth" / f"{index:06d}.png"), frame.depth)
        (tx, ty, tz), (x, y, z, w) = matrix_to_pose(frame.pose.matrix)
        right.append(f"{tx:.6f} {ty:.6f} {tz:.6f} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
        w_first.append(f"{tx:.6f} {ty:.6f} {tz:.6f} {w:.9f} {x:.9f} {y:.9f} {z:.9f}")
    k = frame.intrinsics
    (folder / "camera.json").write_text(json.dumps({
        "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "depth_scale": 1000.0}))
    (folder / "poses.txt").write_text("\n".join(right) + "\n")
    (folder / "poses_wxyz.txt").write_text("\n".join(w_first) + "\n")
    return folder


def test_an_import_says_the_depth_it_found_and_that_the_poses_agree(
        walk_folder: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "walk.mcap"
    assert run_cli("images", "--format", "redwood", str(walk_folder), "--poses",
                   str(walk_folder / "poses.txt"), "--out", str(out)) == 0
    printed = capsys.readouterr().out
    assert "in 24 of 24 frames" in printed and "poses: all 24 agree with the depth" in printed
    low, high = (float(v) for v in printed.split("depth ", 1)[1].split(" m", 1)[0].split("-"))
    assert 0.3 < low < high < 5.0  # the virtual Kinect's range
    assert len(list(read_frames(out))) == 24


def test_poses_written_w_first_are_refused_and_the_order_named(
        walk_folder: Path, tmp_path: Path, caplog) -> None:
    out = tmp_path / "walk.mcap"
    out.write_bytes(b"an earlier recording")
    with caplog.at_level(logging.ERROR):
        assert run_cli("images", "--format", "redwood", str(walk_folder), "--poses",
                       str(walk_folder / "poses_wxyz.txt"), "--out", str(out)) == 2
    assert "likely cause: the quaternions are in w x y z order" in caplog.text
    assert out.read_bytes() == b"an earlier recording"  # untouched
    assert [path.name for path in tmp_path.iterdir()] == ["walk.mcap"]  # no partial file


def test_float_depth_is_refused_with_the_fix(tmp_path: Path, caplog) -> None:
    """A PCL-style folder whose depth TIFF holds float32 metres."""
    stamp = "frame_20240101T000000.000000"
    cv2.imwrite(str(tmp_path / f"{stamp}_rgb.tiff"), np.zeros((48, 64, 3), np.uint8))
    cv2.imwrite(str(tmp_path / f"{stamp}_depth.tiff"), np.full((48, 64), 1.5, np.float32))
    with caplog.at_level(logging.ERROR):
        assert run_cli("images", "--format", "pcl-tiff", str(tmp_path),
                       "--out", str(tmp_path / "x.mcap")) == 2
    assert "depth is float32" in caplog.text and "astype(np.uint16)" in caplog.text


def test_metres_stored_as_integers_are_warned_about(walk_folder: Path, tmp_path: Path,
                                                    caplog, capsys) -> None:
    folder = tmp_path / "metres"
    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    for path in sorted((walk_folder / "depth").iterdir())[:3]:
        millimetres = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(folder / "depth" / path.name),
                    np.rint(millimetres / 1000.0).astype(np.uint16))  # whole metres
        (folder / "color" / path.name).write_bytes((walk_folder / "color" / path.name)
                                                   .read_bytes())
    with caplog.at_level(logging.WARNING):
        assert run_cli("images", "--format", "redwood", str(folder),
                       "--out", str(tmp_path / "m.mcap")) == 0
    assert re.search(r"\(median 0\.00[1-5] m\)", capsys.readouterr().out)  # not metres
    assert "probably in another unit than depth_scale says" in caplog.text


def test_stamps_must_be_finite(tmp_path: Path) -> None:
    poses = tmp_path / "trajectory.txt"
    poses.write_text("1.0 0 0 0 0 0 0 1\nInfinity 0 0 0 0 0 0 1\n")
    with pytest.raises(RecordingError, match=r"trajectory\.txt:2: not finite"):
        pose_files.load_poses(poses)
    poses.write_text("1e300 0 0 0 0 0 0 1\n")
    with pytest.raises(RecordingError, match=r"trajectory\.txt:1: timestamp .* outside"):
        pose_files.load_poses(poses)
    folder = tmp_path / "tum"
    folder.mkdir()
    cv2.imwrite(str(folder / "c.png"), np.zeros((8, 8, 3), np.uint8))
    cv2.imwrite(str(folder / "d.png"), np.zeros((8, 8), np.uint16))
    (folder / "rgb.txt").write_text("inf c.png\n")
    (folder / "depth.txt").write_text("1.0 d.png\n")
    with pytest.raises(RecordingError, match=r"rgb\.txt.*line 1"):
        list(iter_image_frames(folder, "tum"))


def test_pose_files_are_read_as_a_stream_up_to_their_limit(tmp_path: Path,
                                                           monkeypatch) -> None:
    monkeypatch.setattr(pose_files, "MAX_POSES", 1000)
    poses = tmp_path / "long.txt"
    poses.write_text("0 0 0 0 0 0 1\n" * 1001)
    with pytest.raises(RecordingError, match="more than 1,000 poses"):
        pose_files.load_poses(poses)
    poses.write_text("0 " * 5000 + "\n")
    with pytest.raises(RecordingError, match="longer than 4096 characters"):
        pose_files.load_poses(poses)


@pytest.mark.parametrize(("values", "message"), [
    ({"fx": "NaN"}, "must be finite"),
    ({"cx": float("inf")}, "must be finite"),
    ({"depth_scale": 0}, "must be positive"),
    ({"width": -640}, "width and height must be positive"),
])
def test_camera_parameters_must_be_finite_and_positive(tmp_path: Path, values: dict,
                                                       message: str) -> None:
    (tmp_path / "camera.json").write_text(json.dumps(values))
    with pytest.raises(RecordingError, match=message):
        load_camera(tmp_path, "redwood")
