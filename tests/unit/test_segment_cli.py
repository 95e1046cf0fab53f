"""`gngdt segment`: label images and summary from a bundled recording and from real labelled
frames (../shared), bad input named and nothing half-written, profiles validated."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from gngdt.io.mcap.reader import read_frames
from gngdt.io.staged_directory import StagedDirectory
from gngdt.services.cli import main as gngdt

REPO_ROOT = Path(__file__).resolve().parents[2]
SMALL_RECORDING = REPO_ROOT / "recordings" / "tabletop_small.mcap"
LABELLED = REPO_ROOT.parent / "shared" / "data" / "labelled"

#: a cheap profile: the outputs' form is under test here, not the segmentation's quality
SMALL_PROFILE = """
[gngdt]
max_nodes = 400
lambda = 50

[segmentation]
min_segment_nodes = 3

[frames]
steps_first_frame = 20000

[learner]  # the steps of each later frame: one setting for gngdt learn and gngdt segment
samples_per_frame = 4000
"""


@pytest.fixture
def small_profile(tmp_path: Path) -> Path:
    path = tmp_path / "small.toml"
    path.write_text(SMALL_PROFILE)
    return path


def read_labels(path: Path) -> np.ndarray:
    labels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert labels is not None, path
    return labels


def write_redwood(folder: Path, frames: list, camera: bool = True) -> Path:
    """A redwood folder (color/, depth/, camera.json) holding ``frames``."""
    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    for index, frame in enumerate(frames):
        cv2.imwrite(str(folder / "color" / f"{index:06d}.png"), frame.color[..., ::-1])
        cv2.imwrite(str(folder / "depth" / f"{index:06d}.png"), frame.depth)
    if camera:
        k = frames[0].intrinsics
        (folder / "camera.json").write_text(json.dumps({
            "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "width": k.width,
            "height": k.height, "depth_scale": 1000.0}))
    return folder


@pytest.fixture(scope="module")
def recorded_frames() -> list:
    return list(read_frames(SMALL_RECORDING))


def check_outputs(out: Path, names: list[str], depths: list[np.ndarray]) -> dict:
    """Every frame's label image is there, uint16, of its frame's size, 0 where there is no
    depth and at few pixels with depth; the summary agrees with the images. Returns the
    summary."""
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(p.name for p in out.iterdir()) == sorted([f"{n}.png" for n in names]
                                                          + ["summary.json"])
    assert summary["frames"] == len(names) == len(summary["per_frame"])
    for name, depth, entry in zip(names, depths, summary["per_frame"], strict=True):
        labels = read_labels(out / f"{name}.png")
        assert labels.dtype == np.uint16 and labels.shape == depth.shape
        assert entry["name"] == name and (entry["height"], entry["width"]) == depth.shape
        assert (labels[depth == 0] == 0).all()  # aligned with the depth image
        # with depth, 0 only where the nearest node is in no segment (a lone fragment)
        assert np.mean(labels[depth > 0] == 0) < 0.05
        assert 1 < len(np.setdiff1d(labels[depth > 0], [0])) <= entry["segments"]
        assert labels.max() <= entry["segments"]
        assert entry["milliseconds"]["total"] > 0 and "learn" in entry["milliseconds"]
    return summary


def test_segment_a_recording_online_and_independent(
        tmp_path: Path, small_profile: Path, recorded_frames: list, capsys, caplog) -> None:
    depths = [frame.depth for frame in recorded_frames]
    names = [f"{index:06d}" for index in range(len(depths))]
    out = tmp_path / "online"
    with caplog.at_level(logging.INFO):
        assert gngdt(["segment", str(SMALL_RECORDING), "--out", str(out),
                      "--params", str(small_profile)]) == 0
    # the kernels are compiled (or loaded) before the first frame, step by step, and that time
    # is reported apart from the frames'
    assert "compiling kernels 1/2: learning, segmentation and pixel labels" in caplog.text
    assert caplog.text.index("compiling kernels") < caplog.text.index("frame 1/10")
    summary = check_outputs(out, names, depths)
    assert summary["mode"] == "online" and summary["format"] == "mcap"
    assert [entry["steps"] for entry in summary["per_frame"]] == [20000] + [4000] * 9
    assert summary["parameters"]["gngdt"] == {"max_nodes": 400, "lambda_": 50}
    assert summary["parameters"]["segmentation"]["min_segment_nodes"] == 3
    assert summary["parameters"]["profile"] == str(small_profile)
    assert all(0 < entry["nodes"] <= 400 for entry in summary["per_frame"])
    assert summary["milliseconds"]["total"]["p90"] >= summary["milliseconds"]["total"]["p50"]
    assert summary["compile_seconds"] > 0
    assert "wrote 10 label images" in capsys.readouterr().out

    out = tmp_path / "independent"
    assert gngdt(["segment", str(SMALL_RECORDING), "--out", str(out), "--independent",
                  "--params", str(small_profile)]) == 0
    summary = check_outputs(out, names, depths)
    assert summary["mode"] == "independent"
    assert [entry["steps"] for entry in summary["per_frame"]] == [20000] * 10


def test_segment_real_labelled_frames(tmp_path: Path) -> None:
    """Three real frames of each labelled set, default profile, independent; labels ignored."""
    if not LABELLED.is_dir():
        pytest.skip(f"real labelled frames not found at {LABELLED} (the repository's sibling "
                    "../shared)")
    for name, stems in (("mosd_learn", ["000000", "000017", "000044"]),
                        ("ycbv_0000", ["000000"])):
        source = LABELLED / name
        subset = tmp_path / name
        for kind in ("color", "depth", "label"):
            (subset / kind).mkdir(parents=True)
            for stem in stems:
                os.symlink(source / kind / f"{stem}.png", subset / kind / f"{stem}.png")
        os.symlink(source / "camera.json", subset / "camera.json")
        out = tmp_path / f"{name}-out"
        assert gngdt(["segment", str(subset), "--out", str(out), "--independent"]) == 0
        camera = json.loads((source / "camera.json").read_text())
        depths = [cv2.imread(str(source / "depth" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
                  for stem in stems]
        summary = check_outputs(out, stems, depths)
        assert all(d.shape == (camera["height"], camera["width"]) for d in depths)
        assert summary["format"] == "redwood"
        assert summary["intrinsics"]["fx"] == camera["fx"]
        assert summary["intrinsics"]["from"].endswith("camera.json")
        assert summary["parameters"]["profile"].endswith("kinect.toml")  # the default profile


def test_a_folder_without_camera_json_warns_which_intrinsics_are_assumed(
        tmp_path: Path, small_profile: Path, recorded_frames: list, caplog, capsys) -> None:
    folder = write_redwood(tmp_path / "frames", recorded_frames[:2], camera=False)
    out = tmp_path / "out"
    assert gngdt(["segment", str(folder), "--out", str(out), "--params", str(small_profile)]) == 0
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert any("camera.json is missing" in w and "fx=525 " in w and "cy=239.5" in w
               for w in warnings), warnings
    printed = capsys.readouterr().out
    assert "WARNING: fx=525 fy=525 cx=319.5 cy=239.5 px assumed" in printed
    assert "WARNING: depth_scale=1000 units per metre assumed" in printed
    summary = check_outputs(out, ["000000", "000001"], [f.depth for f in recorded_frames[:2]])
    assert summary["intrinsics"]["from"].startswith("ASSUMED")
    width = recorded_frames[0].color.shape[1]  # the defaults are for 640x480: scaled
    assert width != 640 and summary["intrinsics"]["fx"] == 525.0 * width / 640


@pytest.mark.parametrize("damage, message", [
    ("missing depth", "000001.png: no matching depth image"),
    ("unreadable depth", "000001.png: frame 1: cannot read depth image"),
    ("mismatched sizes", "000001.png: frame 1: depth 160x120 does not match colour 320x240"),
])
def test_bad_folders_are_named_and_nothing_is_written(
        tmp_path: Path, small_profile: Path, recorded_frames: list, caplog,
        damage: str, message: str) -> None:
    folder = write_redwood(tmp_path / "frames", recorded_frames[:3])
    depth = folder / "depth" / "000001.png"
    if damage == "missing depth":
        depth.unlink()
    elif damage == "unreadable depth":
        depth.write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    else:
        cv2.imwrite(str(depth), recorded_frames[1].depth[::2, ::2])
    out = tmp_path / "out"
    assert gngdt(["segment", str(folder), "--out", str(out), "--params", str(small_profile)]) == 2
    errors = " ".join(r.getMessage() for r in caplog.records if r.levelname == "ERROR")
    assert message in errors
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames", "small.toml"]  # no leftovers


def test_a_damaged_recording_is_named_and_nothing_is_written(
        tmp_path: Path, small_profile: Path, caplog) -> None:
    truncated = tmp_path / "truncated.mcap"
    data = SMALL_RECORDING.read_bytes()
    truncated.write_bytes(data[: len(data) * 2 // 3])
    out = tmp_path / "out"
    assert gngdt(["segment", str(truncated), "--out", str(out),
                  "--params", str(small_profile)]) == 2
    assert any(str(truncated) in r.getMessage() for r in caplog.records
               if r.levelname == "ERROR")
    assert not out.exists()


def test_an_existing_output_folder_is_kept_unless_overwrite(
        tmp_path: Path, small_profile: Path, recorded_frames: list) -> None:
    folder = write_redwood(tmp_path / "frames", recorded_frames[:1])
    out = tmp_path / "out"
    out.mkdir()
    (out / "precious.txt").write_text("mine")
    argv = ["segment", str(folder), "--out", str(out), "--params", str(small_profile)]
    assert gngdt(argv) == 2
    assert [p.name for p in out.iterdir()] == ["precious.txt"]
    assert gngdt([*argv, "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["000000.png", "summary.json"]


def test_layout_detection_and_format_choice(
        tmp_path: Path, small_profile: Path, recorded_frames: list, caplog) -> None:
    folder = write_redwood(tmp_path / "frames", recorded_frames[:1])
    (folder / "rgb.txt").write_text("# a TUM list too\n")
    (folder / "depth.txt").write_text("# and its depth list\n")
    out = tmp_path / "out"
    argv = ["segment", str(folder), "--out", str(out), "--params", str(small_profile)]
    assert gngdt(argv) == 2
    assert "ambiguous (redwood and tum both match); choose one with --format" in caplog.text
    assert gngdt([*argv, "--format", "redwood"]) == 0
    assert gngdt(["segment", str(tmp_path / "nothing"), "--out", str(tmp_path / "o2")]) == 2
    assert "nothing: no such file or folder" in caplog.text


@pytest.mark.parametrize("text, message", [
    ("[gngdt]\nmax_nodez = 10\n", "unknown key 'max_nodez'"),
    ("[segmentation]\nsmooth_angle = 5.0\n", "unknown segmentation parameter(s) ['smooth_angle']"),
    ("[frames]\nsteps_per_frame = 0\n", "[frames] steps_per_frame must be in [1, inf]"),
    ("[frame]\nsteps_per_frame = 10\n", "unknown table [frame]"),
    ("[gngdt\n", "invalid TOML"),
])
def test_bad_profiles_are_named(tmp_path: Path, caplog, text: str, message: str) -> None:
    profile = tmp_path / "bad.toml"
    profile.write_text(text)
    out = tmp_path / "out"
    assert gngdt(["segment", str(SMALL_RECORDING), "--out", str(out),
                  "--params", str(profile)]) == 2
    assert str(profile) in caplog.text and message in caplog.text
    assert not out.exists()


def test_staged_directory_appears_whole_or_not_at_all(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with pytest.raises(RuntimeError), StagedDirectory(target) as staging:
        (staging / "half.png").write_bytes(b"x")
        raise RuntimeError("failed mid-way")
    assert list(tmp_path.iterdir()) == []
    target.mkdir()
    (target / "old.txt").write_text("old")
    with pytest.raises(ValueError, match="not empty"):
        StagedDirectory(target)
    with pytest.raises(KeyboardInterrupt), StagedDirectory(target, overwrite=True) as staging:
        (staging / "new.txt").write_text("new")
        raise KeyboardInterrupt
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    assert [p.name for p in target.iterdir()] == ["old.txt"]
    with StagedDirectory(target, overwrite=True) as staging:
        (staging / "new.txt").write_text("new")
        assert not (target / "new.txt").exists()  # nothing visible before the end
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    assert [p.name for p in target.iterdir()] == ["new.txt"]
