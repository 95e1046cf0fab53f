"""`gngdt record images --poses`: TUM trajectories, per-frame pose lists and folders, the three
real TUM frames in one world frame, and clear errors for bad pose files."""

from __future__ import annotations

import logging
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from helpers.image_folders import TUM, build_tum_folder, run_cli
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from gngdt.io.deproject import Deprojector
from gngdt.io.errors import RecordingError
from gngdt.io.mcap.reader import read_frames
from gngdt.io.pose_files import attach_poses, load_poses


@pytest.fixture
def rgbd() -> Path:
    if not TUM.is_dir():
        pytest.skip(f"real TUM samples not found at {TUM} (the repository's sibling ../shared)")
    return TUM.parent


def tum_line(matrix: np.ndarray, stamp: str | None = None) -> str:
    x, y, z = matrix[:3, 3]
    qx, qy, qz, qw = Rotation.from_matrix(matrix[:3, :3]).as_quat()
    values = " ".join(f"{v:.9f}" for v in (x, y, z, qx, qy, qz, qw))
    return values if stamp is None else f"{stamp} {values}"


def pose(angle: float, x: float) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_rotvec([0.0, angle, 0.0]).as_matrix()
    matrix[:3, 3] = [x, 0.5, 1.0]
    return matrix


def test_the_three_tum_frames_land_in_one_world_frame(rgbd: Path, tmp_path: Path):
    out = tmp_path / "tum3.mcap"
    assert run_cli("images", "--format", "redwood", str(TUM), "--poses", str(TUM / "poses"),
                   "--out", str(out)) == 0
    frames = list(read_frames(out))
    for index, frame in enumerate(frames):
        values = [float(v) for v in (TUM / "poses" / f"{index:06d}.txt").read_text().split()]
        np.testing.assert_allclose(frame.pose.position, values[:3], atol=1e-12)
        assert frame.pose.frame_id == "world"
    deproject = Deprojector()
    camera = [deproject(f.depth, None, f.intrinsics)[0].astype(np.float64) for f in frames]
    world = [points @ f.pose.matrix[:3, :3].T + f.pose.matrix[:3, 3]
             for points, f in zip(camera, frames, strict=True)]
    for i, j in ((0, 1), (0, 2), (1, 2)):
        in_world = np.median(cKDTree(world[j]).query(world[i][::50])[0])
        in_camera = np.median(cKDTree(camera[j]).query(camera[i][::50])[0])
        # measured: 3-6 mm with the poses, 22-48 mm without
        assert in_world < 0.008 and in_world < in_camera / 3, (i, j, in_world, in_camera)


def test_a_tum_trajectory_is_interpolated_at_each_frame(rgbd: Path, tmp_path: Path):
    stamps = build_tum_folder(tmp_path / "fr1")
    trajectory = tmp_path / "groundtruth.txt"
    # 10 Hz ground truth around the frames (1305031102.175-.275 s): pose(t) linear in t
    times = [1305031102.1 + 0.1 * k for k in range(4)]
    lines = ["# ground truth trajectory", "# timestamp tx ty tz qx qy qz qw"]
    lines += [tum_line(pose(0.2 * k, 1.0 * k), f"{t:.6f}") for k, t in enumerate(times)]
    trajectory.write_text("\n".join(lines) + "\n")
    out = tmp_path / "fr1.mcap"
    assert run_cli("images", "--format", "tum", str(tmp_path / "fr1"), "--poses",
                   str(trajectory), "--out", str(out)) == 0
    for frame, (rgb_stamp, _) in zip(read_frames(out), stamps, strict=True):
        k = float((Decimal(rgb_stamp) - Decimal("1305031102.1")) / Decimal("0.1"))
        np.testing.assert_allclose(frame.pose.matrix, pose(0.2 * k, 1.0 * k), atol=1e-6)


def test_a_trajectory_that_misses_a_frame_is_an_error_naming_it(rgbd: Path, tmp_path: Path):
    build_tum_folder(tmp_path / "fr1")
    trajectory = tmp_path / "short.txt"
    trajectory.write_text(tum_line(pose(0, 0), "1305031102.17") + "\n"
                          + tum_line(pose(0, 1), "1305031102.22") + "\n")
    frames = iter_frames(tmp_path / "fr1", "tum")
    with pytest.raises(RecordingError, match=r"short\.txt: frame 2: no pose.*1305031102\.275"):
        list(attach_poses(frames, load_poses(trajectory), 3))


def iter_frames(directory: Path, fmt: str):
    from gngdt.io.images import iter_image_frames

    return iter_image_frames(directory, fmt)


def test_a_per_frame_list_shorter_than_the_frames_is_refused_before_writing(
    rgbd: Path, tmp_path: Path, caplog
):
    listing = tmp_path / "poses.txt"
    listing.write_text(tum_line(pose(0, 0)) + "\n" + tum_line(pose(0, 1)) + "\n")
    out = tmp_path / "never.mcap"
    with caplog.at_level(logging.ERROR):
        status = run_cli("images", "--format", "redwood", str(TUM), "--poses", str(listing),
                         "--out", str(out))
    assert status == 2 and not out.exists()
    assert "poses.txt: 2 poses for 3 frames" in caplog.text
    # one pose per frame, in frame order: accepted
    listing.write_text("\n".join(tum_line(pose(0, x)) for x in (0, 1, 2, 3)) + "\n")
    frames = list(attach_poses(iter_frames(TUM, "redwood"), load_poses(listing), 3))
    assert [f.pose.position[0] for f in frames] == pytest.approx([0, 1, 2])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("1 2 3 0 0 0 1\n1 2 three 0 0 0 1\n", r"poses\.txt:2: not a list of numbers"),
        ("1 2 3 0 0 0 1\n1 2 3 0 0 1\n", r"poses\.txt:2: expected 8 numbers .* got 6"),
        ("1 2 3 0 0 0 1\n1 2 3 0 0 0 2\n", r"poses\.txt:2: .*norm 2\.0000"),
        ("# nothing\n", "no poses"),
        ("1.0 0 0 0 1 1 0 0\n", r"poses\.txt:1: .*norm 1\.4142.*qx qy qz qw"),
    ],
)
def test_bad_pose_files_name_the_file_and_line(tmp_path: Path, content: str, message: str):
    path = tmp_path / "poses.txt"
    path.write_text(content)
    with pytest.raises(RecordingError, match=message):
        load_poses(path)


def test_a_folder_of_matrices_is_read_in_name_order(tmp_path: Path):
    folder = tmp_path / "pose"
    folder.mkdir()
    for index in (0, 1, 10, 2):  # natural order: 0, 1, 2, 10
        matrix = pose(0.1 * index, float(index))
        (folder / f"frame-{index}.pose.txt").write_text(
            "\n".join(" ".join(f"{v:.12f}" for v in row) for row in matrix) + "\n")
    poses = load_poses(folder)
    assert [m[0, 3] for m in poses.matrices] == [0.0, 1.0, 2.0, 10.0]
    (folder / "frame-2.pose.txt").write_text("1 0 0 0\n0 2 0 0\n0 0 1 0\n0 0 0 1\n")
    with pytest.raises(RecordingError, match=r"frame-2\.pose\.txt: not a rigid 4x4"):
        load_poses(folder)
