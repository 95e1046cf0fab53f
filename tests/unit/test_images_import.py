"""Import real RGB-D frames (../shared/data/rgbd) with every layout, and the `record images` CLI."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers.image_folders import RGBD, TUM, build_tum_folder, run_cli

from gngdt.io.errors import RecordingError
from gngdt.io.images import iter_image_frames
from gngdt.io.mcap.reader import read_frames

#: folder -> (format, frames) as listed in ../shared/data/rgbd/README.md
DATASETS = {
    "pcl_grabber_sequence": ("pcl-tiff", 3),
    "pcl_milk_cartoon_organized_kinect": ("redwood", 1),
    "rtabmap_rgbd_test": ("redwood", 2),
    "tum_fr1_xyz_dvo_examples": ("redwood", 3),
}


@pytest.fixture(scope="module")
def rgbd() -> Path:
    if not RGBD.is_dir():
        pytest.skip(f"real RGB-D samples not found at {RGBD} (the repository's sibling ../shared)")
    return RGBD


@pytest.mark.parametrize("folder", sorted(DATASETS))
def test_every_sample_dataset_imports(rgbd: Path, folder: str) -> None:
    fmt, count = DATASETS[folder]
    camera = json.loads((rgbd / folder / "camera.json").read_text())
    frames = list(iter_image_frames(rgbd / folder, fmt))
    assert len(frames) == count
    for frame in frames:
        assert frame.color.shape == (camera["height"], camera["width"], 3)
        assert frame.color.dtype == np.uint8 and frame.depth.dtype == np.uint16
        assert (frame.intrinsics.fx, frame.intrinsics.cy) == (camera["fx"], camera["cy"])
        raw_depth = cv2.imread(str(frame.depth_path), cv2.IMREAD_UNCHANGED)
        expected_mm = np.rint(raw_depth * (1000.0 / camera["depth_scale"])).astype(np.uint16)
        np.testing.assert_array_equal(frame.depth, expected_mm)
        valid = frame.depth[frame.depth > 0]
        assert 300 < np.median(valid) < 5000  # indoor scenes: metres, not TUM units
        bgr = cv2.imread(str(frame.color_path), cv2.IMREAD_COLOR)
        np.testing.assert_array_equal(frame.color, bgr[..., ::-1])
    stamps = [frame.timestamp_ns for frame in frames]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)


def test_pcl_tiff_timestamps_come_from_file_names(rgbd: Path) -> None:
    frames = list(iter_image_frames(rgbd / "pcl_grabber_sequence", "pcl-tiff"))
    # frame_20121214T142255.814212 -> 2012-12-14 14:22:55.814212 UTC
    assert frames[0].timestamp_ns == 1355494975_814212000
    assert frames[1].timestamp_ns - frames[0].timestamp_ns == 254_471_000


def test_tum_layout(rgbd: Path, tmp_path: Path) -> None:
    stamps = build_tum_folder(tmp_path / "fr1")
    frames = list(iter_image_frames(tmp_path / "fr1", "tum"))
    assert [frame.timestamp_ns for frame in frames] == [
        int(rgb.replace(".", "")) * 1000 for rgb, _ in stamps
    ]
    intrinsics = frames[0].intrinsics
    assert (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy) == (
        517.3,
        516.5,
        318.6,
        255.3,
    )
    for index, frame in enumerate(frames):
        raw = cv2.imread(str(TUM / "depth" / f"{index:06d}.png"), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(frame.depth, np.rint(raw / 5.0).astype(np.uint16))


def test_record_images_cli_writes_a_readable_recording(rgbd: Path, tmp_path: Path) -> None:
    out = tmp_path / "lab.mcap"
    assert (
        run_cli(
            "images",
            "--format",
            "redwood",
            str(rgbd / "rtabmap_rgbd_test"),
            "--out",
            str(out),
            "--fx",
            "530",
        )
        == 0
    )
    imported = list(iter_image_frames(rgbd / "rtabmap_rgbd_test", "redwood"))
    recorded = list(read_frames(out))
    assert len(recorded) == len(imported) == 2
    for original, copy in zip(imported, recorded, strict=True):
        np.testing.assert_array_equal(copy.color, original.color)
        np.testing.assert_array_equal(copy.depth, original.depth)
        assert copy.intrinsics.fx == 530 and copy.intrinsics.fy == 525


def test_record_images_cli_tum_depth_scale_override(rgbd: Path, tmp_path: Path) -> None:
    build_tum_folder(tmp_path / "fr1")
    out = tmp_path / "fr1.mcap"
    assert (
        run_cli(
            "images",
            "--format",
            "tum",
            str(tmp_path / "fr1"),
            "--out",
            str(out),
            "--depth-scale",
            "1000",
        )
        == 0
    )
    raw = cv2.imread(str(TUM / "depth" / "000000.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(next(read_frames(out)).depth, raw)


def test_unpaired_and_missing_files_are_clear_errors(rgbd: Path, tmp_path: Path) -> None:
    folder = tmp_path / "redwood"
    shutil.copytree(rgbd / "rtabmap_rgbd_test", folder)
    (folder / "depth" / "000154.png").unlink()
    with pytest.raises(RecordingError, match=r"000154\.jpg: no matching depth image"):
        list(iter_image_frames(folder, "redwood"))
    with pytest.raises(RecordingError, match=r"rgb\.txt: missing"):
        list(iter_image_frames(folder, "tum"))
    with pytest.raises(RecordingError, match="not a directory"):
        list(iter_image_frames(tmp_path / "nothing", "redwood"))
    (folder / "depth" / "000017.png").write_bytes(b"not a png")
    (folder / "color" / "000154.jpg").unlink()
    with pytest.raises(RecordingError, match=r"000017\.png: frame 0: cannot read depth"):
        list(iter_image_frames(folder, "redwood"))
    assert (
        run_cli("images", "--format", "redwood", str(folder), "--out", str(tmp_path / "x.mcap"))
        == 2
    )


def test_tum_pairs_follow_associate_py_closest_pairs_first() -> None:
    """Colour c1 is nearest to depth d0, which colour c0 also wants: taking each colour's nearest
    depth in turn loses c1's frame; TUM's associate.py takes the closest pair (c1, d0) first and
    still pairs c0 with d1 (19 ms apart, within 20 ms)."""
    from gngdt.io.images import associate

    ms = 1_000_000
    colors, depths = [0, 10 * ms], [6 * ms, 19 * ms]
    assert associate(colors, depths, 20 * ms) == [(0, 1), (1, 0)]
    assert associate(colors, depths, 10 * ms) == [(1, 0)]  # (c0, d1) is 19 ms apart
    assert associate([0, 5, 9], [1, 8, 100], 3) == [(0, 0), (2, 1)]  # each image used once


def test_a_tum_colour_image_without_depth_is_said_once(tmp_path: Path, caplog) -> None:
    folder = tmp_path / "tum"
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    color, depth = np.zeros((4, 4, 3), np.uint8), np.full((4, 4), 5000, np.uint16)
    rgb_lines, depth_lines = [], []
    for stamp in ("10.000", "10.010", "10.500"):  # the last has no depth near it
        cv2.imwrite(str(folder / "rgb" / f"{stamp}.png"), color)
        rgb_lines.append(f"{stamp} rgb/{stamp}.png")
    for stamp in ("10.006", "10.019"):
        cv2.imwrite(str(folder / "depth" / f"{stamp}.png"), depth)
        depth_lines.append(f"{stamp} depth/{stamp}.png")
    (folder / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (folder / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    with caplog.at_level(logging.INFO):
        frames = list(iter_image_frames(folder, "tum"))
    assert len(frames) == 2  # both close colour images kept (associate.py's rule)
    notes = [record for record in caplog.records if "no depth image" in record.getMessage()]
    assert len(notes) == 1 and notes[0].levelno == logging.WARNING
    assert "1 of 3 colour images" in notes[0].getMessage()
