"""``gngdt eval recording`` on a tiny synthetic recording (real MCAP written by our writer)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gngdt.core.learner.frame_learner import LearnerOptions
from gngdt.eval.recording_eval import RecordingSettings, deproject_labels, frame_points
from gngdt.io.deproject import Deprojector
from gngdt.io.frame import CameraIntrinsics
from gngdt.io.mcap.reader import read_frames
from gngdt.services.cli import main as gngdt_main

FRAMES = 3


@pytest.fixture(scope="module")
def tiny_recording(tmp_path_factory) -> Path:
    """3 frames of the tabletop scene at 160x120 with ground-truth labels."""
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = tmp_path_factory.mktemp("recordings") / "tabletop_tiny.mcap"
    with RecordingWriter(path) as writer:
        for frame in render_scene("tabletop", FRAMES, width=160, height=120, seed=3):
            writer.write_frame(frame)
    return path


def test_labels_follow_the_deprojected_points() -> None:
    intrinsics = CameraIntrinsics(width=4, height=2, fx=2.0, fy=2.0, cx=2.0, cy=1.0)
    depth = np.array([[0, 1000, 2000, 0], [500, 0, 30_000, 1500]], dtype=np.uint16)
    labels = np.array([[1, 300, 2, 3], [65_000, 4, 5, 7]], dtype=np.uint16)
    deproject = Deprojector(0.1, 10.0)
    positions, _ = deproject(depth, np.zeros((2, 4, 3), np.uint8), intrinsics)
    point_labels = deproject_labels(deproject, depth, labels, intrinsics)
    # valid: 1000 mm, 2000 mm, 500 mm, 1500 mm (30 m is out of range), row-major order
    np.testing.assert_array_equal(point_labels, [300, 2, 65_000, 7])
    np.testing.assert_allclose(positions[:, 2], [1.0, 2.0, 0.5, 1.5])


def test_replay_sees_the_points_the_capture_would(tiny_recording) -> None:
    frames = list(frame_points(tiny_recording, RecordingSettings(max_nodes=50)))
    assert len(frames) == FRAMES
    for points, frame in zip(frames, read_frames(tiny_recording), strict=True):
        valid = (frame.depth >= 100) & (frame.depth <= 10_000)
        assert len(points.positions) == int(valid.sum())
        np.testing.assert_array_equal(points.labels, frame.labels[valid])
        np.testing.assert_array_equal(points.colors, frame.color[valid])


@pytest.mark.timeout(300)
def test_eval_recording_report(tiny_recording, tmp_path) -> None:
    out = tmp_path / "report"
    argv = [
        "eval",
        "recording",
        str(tiny_recording),
        "--out",
        str(out),
        "--method",
        "gngdt",
        "gng",
        "--samples-per-frame",
        "3000",
        "--max-nodes",
        "60",
        "--reference-points",
        "4000",
        "--object-confirm-frames",  # 3 frames: objects at once, so identity is scored
        "1",
        "--no-progress",
    ]
    assert gngdt_main(argv) == 0
    data = json.loads((out / "recording.json").read_text())
    assert data["labelled"] is True
    assert [r["method"] for r in data["runs"]] == ["GNG", "GNG-DT"]
    gngdt = next(r for r in data["runs"] if r["method"] == "GNG-DT")
    assert len(gngdt["frames"]) == FRAMES
    last = gngdt["frames"][-1]
    # the recording has camera poses: its map's first frame is learned longer, as the learner's
    assert last["steps"] == LearnerOptions().first_frame_steps + (FRAMES - 1) * 3000
    assert 2 < last["nodes"] <= 60
    assert set(last["clusters"]) == {"pos", "col", "nor", "col+nor"}
    assert set(last["ari"]) == {"pos", "col", "nor", "col+nor"}
    assert all(-1.0 <= v <= 1.0 for v in last["ari"].values())
    # far better than one node at the centroid of the frame's points
    positions = list(frame_points(tiny_recording, RecordingSettings()))[-1].positions
    single_node_error = np.sqrt(np.mean(np.sum((positions - positions.mean(0)) ** 2, axis=1)))
    assert 0 < last["qe_pos"] < 0.5 * single_node_error
    summary = data["summary"]["GNG-DT"]
    references = data["references"]["by_nodes"][str(last["nodes"])]
    # k-means with the same number of centres: a learned topology cannot beat it by much
    assert summary["ratio_to_kmeans_pos"] > 0.8
    assert references["voxel_grid"]["points"] == pytest.approx(last["nodes"], rel=0.2)
    dbscan = data["references"]["dbscan"]
    assert -1.0 <= dbscan["ari"] <= 1.0 and dbscan["points"] <= 4000
    identity = summary["identity"]
    assert set(identity) == {"pos", "col", "nor", "col+nor", "segments"}
    assert identity["pos"]["id_comparisons"] > 0  # every labelled segment, frame to frame
    assert 0.0 <= identity["pos"]["id_kept"]["mean"] <= 1.0
    markdown = (out / "recording.md").read_text()
    assert "seen in 1 frame(s) in a row" in markdown
    for heading in ("## Last frame, per method", "## References on the last frame", "## Per frame",
                    "## Object identity"):
        assert heading in markdown
    for plot in data["plots"]:
        assert (out / plot).stat().st_size > 1000


def test_eval_recording_on_missing_file_is_a_clear_error(tmp_path, capsys) -> None:
    missing = tmp_path / "nope.mcap"
    assert gngdt_main(["eval", "recording", str(missing), "--out", str(tmp_path / "o")]) == 2
    assert "nope.mcap" in capsys.readouterr().err


def test_eval_recording_on_a_broken_file_is_one_line(tmp_path, capsys) -> None:
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"\x89MCAP0\r\n" + b"not really" * 100)
    assert gngdt_main(["eval", "recording", str(broken), "--out", str(tmp_path / "o")]) == 2
    error = capsys.readouterr().err
    assert "broken.mcap" in error and "Traceback" not in error


@pytest.mark.timeout(300)
def test_eval_recording_without_labels(tmp_path) -> None:
    """Real-frame recordings have no ground truth: no ARI, everything else reported."""
    from dataclasses import replace

    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = tmp_path / "unlabelled.mcap"
    with RecordingWriter(path) as writer:
        for frame in render_scene("tabletop", 2, width=160, height=120, seed=5):
            writer.write_frame(replace(frame, labels=None))
    out = tmp_path / "report"
    argv = [
        "eval",
        "recording",
        str(path),
        "--out",
        str(out),
        "--method",
        "gngdt",
        "--samples-per-frame",
        "2000",
        "--max-nodes",
        "30",
        "--reference-points",
        "3000",
        "--no-progress",
    ]
    assert gngdt_main(argv) == 0
    data = json.loads((out / "recording.json").read_text())
    assert data["labelled"] is False
    frames = data["runs"][0]["frames"]
    assert len(frames) == 2 and all("ari" not in f for f in frames)
    assert "ari" not in data["summary"]["GNG-DT"]
    assert "ari" not in data["references"]["dbscan"]
    assert data["references"]["dbscan"]["clusters"] >= 1
    assert "ARI" not in (out / "recording.md").read_text().split("## References")[0]


@pytest.mark.timeout(300)
def test_eval_recording_reports_metrics_over_time_for_a_changing_scene(tmp_path) -> None:
    """tabletop_vanish at 10 fps: the red box vanishes at frame 20; world frame from the poses."""
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import SCENE_METADATA, render_scene, scene_metadata
    from gngdt.io.synth.scenes import build_scene

    path = tmp_path / "vanish.mcap"
    with RecordingWriter(path) as writer:
        writer.add_metadata(SCENE_METADATA, scene_metadata(build_scene("tabletop_vanish"), 10.0))
        for frame in render_scene("tabletop_vanish", 22, width=160, height=120, fps=10.0):
            writer.write_frame(frame)
    out = tmp_path / "report"
    argv = ["eval", "recording", str(path), "--out", str(out), "--method", "gngdt",
            "--samples-per-frame", "3000", "--max-nodes", "100", "--reference-points", "3000",
            "--utility-k", "1000", "--reference-every", "10", "--world-sample", "3000",
            "--no-progress"]
    assert gngdt_main(argv) == 0
    data = json.loads((out / "recording.json").read_text())
    assert data["posed"] is True and data["settings"]["utility_k"] == 1000
    frames = data["runs"][0]["frames"]
    for frame in frames:
        dynamics = frame["dynamics"]
        assert 0 <= dynamics["ghost_nodes"] <= dynamics["seen_nodes"] <= frame["nodes"]
        assert 0.0 <= dynamics["ghost_share"] <= 1.0 and 0.0 <= dynamics["stale_share"] <= 1.0
    # k-means on the world seen so far at frames 9 and 19 and on the last
    referenced = [f["frame"] for f in frames if "world_ratio_to_kmeans" in f["dynamics"]]
    assert referenced == [9, 19, 21]
    assert all(f["dynamics"]["world_ratio_to_kmeans"] > 0.8 for f in frames
               if f["frame"] in referenced)
    assert all("old_place_nodes/red_box" in f["dynamics"] for f in frames[20:])
    over = data["summary"]["GNG-DT"]["over_time"]
    change = over["changes"]["red_box"]
    assert change["kind"] == "vanish" and change["settled_frame"] == 20
    assert change["old_place_nodes_at_change"] >= 0
    assert over["nodes_max"]["mean"] <= 100
    markdown = (out / "recording.md").read_text()
    assert "## Over time" in markdown and "red_box" in markdown and "5 cm" in markdown
    assert (out / "recording_over_time.png").stat().st_size > 1000
    # poses ignored (--camera-frame): the camera frame, as the points came
    settings = RecordingSettings(world_frame=False, max_frames=2)
    for points in frame_points(path, settings):
        assert points.pose is None and points.positions is points.camera_positions


def test_identity_score_counts_switches_and_kept_tracks() -> None:
    from gngdt.eval.identity import MIN_SEGMENT_POINTS, IdentityScore

    score = IdentityScore(min_size=1, confirm_frames=1)
    node_ids = np.arange(4)
    truth = np.repeat([7, 8], MIN_SEGMENT_POINTS)  # two segments, each on its own node pair
    winners = np.repeat([0, 2], MIN_SEGMENT_POINTS)
    first = score.update("c", node_ids, np.array([0, 0, 1, 1]), winners, truth)
    # relabelled (ids persist): no switch
    score.update("c", node_ids, np.array([1, 1, 0, 0]), winners, truth)
    # segment 8's nodes now in a cluster of all-new nodes: a new id, one switch
    ids = score.update("c", np.array([0, 1, 10, 11]), np.array([0, 0, 1, 1]), winners, truth)
    assert ids[2] not in first
    result = score.summary()["c"]
    assert result["id_comparisons"] == 4 and result["id_switches"] == 1
    assert result["id_kept"] == 0.75
    assert result["tracks_kept"] == 3 / 4  # 2 of 2 kept, then 1 of 2
    assert IdentityScore(1, 1).summary() == {}


def test_identity_scores_only_the_objects_the_learner_would_publish() -> None:
    from gngdt.eval.identity import MIN_SEGMENT_POINTS, IdentityScore

    node_ids = np.arange(5)
    truth = np.repeat([7, 8], MIN_SEGMENT_POINTS)  # segment 7 on node 0, segment 8 on node 4
    winners = np.repeat([0, 4], MIN_SEGMENT_POINTS)
    whole, split = np.zeros(5, int), np.array([0, 0, 0, 1, 1])
    # nodes 3-4 split off for one frame and merge back
    frames = (whole, whole, split, whole, whole)
    at_once = IdentityScore(min_size=2, confirm_frames=1)
    for labels in frames:
        at_once.update("c", node_ids, labels, winners, truth)
    assert at_once.summary()["c"]["id_switches"] == 2  # segment 8: to the fragment and back
    score = IdentityScore(min_size=2, confirm_frames=2)
    published = [score.update("c", node_ids, labels, winners, truth) for labels in frames]
    assert (published[0] == -1).all()  # seen once: not an object yet
    assert all(len(set(objects[:3].tolist())) == 1 and objects[0] >= 0 for objects in published[1:])
    assert (published[2][3:] == -1).all()  # the fragment is no object: seen once
    result = score.summary()["c"]
    # the fragment was never an object: no switch, and the object was kept throughout
    assert result["id_switches"] == 0 and result["id_comparisons"] == 5
    assert result["tracks_kept"] == 1.0
