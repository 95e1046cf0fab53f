"""`gngdt eval segmentation`: the score against hand-made label images with known IoUs, the
report on a labelled set made from a bundled recording and on real labelled frames (../shared),
the Open3D peer when it is installed and the report saying why when it is not."""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from gngdt.eval.segment_scores import score_frame, summarize_scores
from gngdt.io.mcap.reader import read_frames
from gngdt.services.cli import main as gngdt

REPO_ROOT = Path(__file__).resolve().parents[2]
SMALL_RECORDING = REPO_ROOT / "recordings" / "tabletop_small.mcap"
LABELLED = REPO_ROOT.parent / "shared" / "data" / "labelled"
HAS_OPEN3D = importlib.util.find_spec("open3d") is not None

SMALL_PROFILE = """
[gngdt]
max_nodes = 400
lambda = 50

[frames]
steps_first_frame = 20000
steps_per_frame = 4000
"""

# ------------------------------------------------------------------------- hand-made scores
TRUTH = np.array([[0, 1, 1, 1, 1, 1],
                  [2, 2, 2, 1, 3, 3],
                  [2, 2, 2, 1, 3, 3],
                  [0, 0, 1, 1, 1, 1]])
PREDICTED = np.array([[5, 5, 0, 0, 0, 0],
                      [1, 1, 1, 1, 4, 0],
                      [1, 1, 0, 0, 4, 0],
                      [9, 9, 0, 0, 0, 0]])


def test_best_iou_counts_unassigned_and_background_pixels_and_ignores_label_zero() -> None:
    score = score_frame(TRUTH, PREDICTED)
    # segment 2 (6 px): predicted 1 covers 5 of them and 1 background pixel -> 5 / (6 + 6 - 5)
    # segment 3 (4 px): predicted 4 covers 2, the other 2 are unassigned -> 2 / (4 + 2 - 2)
    assert score.best_iou == pytest.approx({2: 5 / 7, 3: 0.5})
    assert score.mean_best_iou == pytest.approx((5 / 7 + 0.5) / 2)
    assert score.recall(0.5) == 1.0 and score.recall(0.75) == 0.0
    # 9 lies only on label-0 pixels: not a predicted segment; 5 has one background pixel
    assert score.n_predicted == 3


def test_pixels_without_depth_are_not_scored() -> None:
    valid = np.ones(TRUTH.shape, dtype=bool)
    valid[1, 2] = False  # in segment 2 and in predicted 1
    score = score_frame(TRUTH, PREDICTED, valid)
    assert score.best_iou[2] == pytest.approx(4 / (5 + 5 - 4))
    assert score.best_iou[3] == pytest.approx(0.5)


def test_label_numbers_do_not_matter_and_missing_segments_score_zero() -> None:
    permuted = np.where(TRUTH == 2, 7, np.where(TRUTH == 3, 2, np.where(TRUTH == 1, 3, 0)))
    perfect = score_frame(TRUTH, permuted)
    assert perfect.best_iou == {2: 1.0, 3: 1.0} and perfect.n_predicted == 3
    nothing = score_frame(TRUTH, np.zeros_like(TRUTH))
    assert nothing.best_iou == {2: 0.0, 3: 0.0} and nothing.n_predicted == 0
    merged = score_frame(TRUTH, np.ones_like(TRUTH))  # one segment over everything
    assert merged.best_iou == pytest.approx({2: 6 / 21, 3: 4 / 21})


def test_a_set_is_scored_over_all_its_segments_not_per_frame() -> None:
    first = score_frame(TRUTH, PREDICTED)
    second = score_frame(TRUTH[:, :3], TRUTH[:, :3])  # segment 2 only, perfectly
    background_only = score_frame(np.ones((2, 2), int), np.ones((2, 2), int))
    assert background_only.best_iou == {} and np.isnan(background_only.mean_best_iou)
    summary = summarize_scores([first, second, background_only])
    assert summary["mean_best_iou"] == pytest.approx((5 / 7 + 0.5 + 1.0) / 3)
    assert summary["recall_50"] == 1.0
    assert summary["recall_75"] == pytest.approx(1 / 3)
    assert summary["segments_per_frame"] == pytest.approx((3 + 2 + 1) / 3)
    assert summary["truth_segments"] == 3


def test_failure_modes_are_counted_per_object() -> None:
    # one row of pixels: 1 = background; objects 2 (10 px), 3 (10), 4 (5), 5 (4), 6 (4)
    truth = np.array([[2] * 10 + [3] * 10 + [4] * 5 + [5] * 4 + [1] * 20 + [6] * 4])
    predicted = np.array([[1] * 6 + [2] * 4      # object 2: split 6 / 4 -> fragmented
                          + [3] * 15             # objects 3 and 4 in one segment -> merged,
                          + [4] * 24             # and 4 is not its majority -> missed too
                          + [5] * 4])            # object 5 inside the table's segment: missed
    score = score_frame(truth, predicted)
    assert score.failures == {2: {"fragmented"}, 3: {"merged"}, 4: {"merged", "missed"},
                              5: {"missed"}, 6: set()}
    assert score.failure_counts.as_dict() == {"objects": 5, "fragmented": 1, "merged": 2,
                                              "missed": 2}
    # unassigned pixels: the object is fragmented and missed
    alone = score_frame(truth, np.where(truth == 6, 0, predicted))
    assert alone.failures[6] == {"fragmented", "missed"}
    summary = summarize_scores([score, alone])
    assert (summary["fragmented"], summary["merged"], summary["missed"]) == (3, 4, 5)


def test_scores_refuse_mismatched_images() -> None:
    with pytest.raises(ValueError, match="differ"):
        score_frame(TRUTH, PREDICTED[:, :4])


# ---------------------------------------------------------------------------- the report
@pytest.fixture(scope="module")
def synthetic_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A labelled set from 3 frames of the bundled tabletop recording: every rendered face a
    ground-truth segment (synthetic id + 1), 0 where there is no depth."""
    folder = tmp_path_factory.mktemp("labelled") / "tabletop"
    for kind in ("color", "depth", "label"):
        (folder / kind).mkdir(parents=True)
    frames = list(read_frames(SMALL_RECORDING))[:3]
    for index, frame in enumerate(frames):
        name = f"{index:06d}.png"
        cv2.imwrite(str(folder / "color" / name), frame.color[..., ::-1])
        cv2.imwrite(str(folder / "depth" / name), frame.depth)
        truth = np.where(frame.depth > 0, frame.labels.astype(np.int64) + 1, 0)
        cv2.imwrite(str(folder / "label" / name), truth.astype(np.uint16))
    k = frames[0].intrinsics
    (folder / "camera.json").write_text(json.dumps(
        {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "width": k.width, "height": k.height,
         "depth_scale": 1000.0}))
    return folder


@pytest.fixture
def small_profile(tmp_path: Path) -> Path:
    path = tmp_path / "small.toml"
    path.write_text(SMALL_PROFILE)
    return path


def run_eval(set_dir: Path, out: Path, *options: str) -> dict:
    assert gngdt(["eval", "segmentation", str(set_dir), "--out", str(out), "--no-progress",
                  *options]) == 0
    return json.loads((out / "segmentation.json").read_text())


def check_report(data: dict, out: Path, names: list[str], methods: list[str]) -> None:
    assert list(data["methods"]) == methods
    for method in methods:
        entry = data["methods"][method]
        assert [record["name"] for record in entry["per_frame"]] == names
        summary = entry["summary"]
        for key in ("mean_best_iou", "recall_50", "recall_75"):
            assert 0.0 <= summary[key] <= 1.0, (method, key)
        assert summary["recall_75"] <= summary["recall_50"]
        assert summary["segments_per_frame"] >= 1
        ious = [iou for r in entry["per_frame"] for iou in r["best_iou"].values()]
        assert summary["mean_best_iou"] == pytest.approx(np.mean(ious))
        assert entry["milliseconds"]["total"]["p50"] > 0
    markdown = (out / "segmentation.md").read_text()
    for method in methods:
        assert f"| {method} |" in markdown and f"### {method}" in markdown
    for figure in data["figures"]:
        image = cv2.imread(str(out / figure))
        assert image is not None and image.shape[1] > image.shape[0]
        assert f"]({figure})" in markdown


def test_report_on_a_labelled_recording_with_both_modes(
        synthetic_set: Path, small_profile: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "report"
    data = run_eval(synthetic_set, out, "--independent", "--online", "--params",
                    str(small_profile), "--figures", "2")
    names = ["000000", "000001", "000002"]
    methods = ["gngdt independent", "gngdt online"] + (["open3d peer"] if HAS_OPEN3D else [])
    check_report(data, out, names, methods)
    # two frames spread over the set, and gngdt's worst (here all three), worst first
    lowest = {name: min(r["mean_best_iou"] for m in methods[:2]
                        for r in data["methods"][m]["per_frame"] if r["name"] == name)
              for name in names}
    assert data["worst_frames"] == sorted(names, key=lambda name: (lowest[name], name))
    assert data["figures"] == [f"segmentation_{name}.png" for name in names]
    for method in methods:
        for record in data["methods"][method]["per_frame"]:
            assert record["objects"] == record["truth_segments"]
            assert all(0 <= record[key] <= record["objects"]
                       for key in ("fragmented", "merged", "missed"))
    assert "## Failures" in (out / "segmentation.md").read_text()
    assert data["gngdt"]["parameters"]["frames"]["steps_first_frame"] == 20000
    steps = [r["steps"] for r in data["methods"]["gngdt online"]["per_frame"]]
    assert steps == [20000, 4000, 4000]
    assert "mean best IoU" in capsys.readouterr().out


@pytest.mark.skipif(not HAS_OPEN3D, reason="open3d is not installed (the optional extra: "
                    "pip install -e '.[peers]'); its absence is tested below")
def test_the_peer_segments_a_plane_and_clusters(synthetic_set: Path, tmp_path: Path) -> None:
    import open3d

    from gngdt.eval.open3d_peer import Open3DPeer, PeerParams
    from gngdt.io.segment_frames import organized_frames
    from gngdt.io.sources import open_source

    _, frame, points, _ = next(organized_frames(open_source(synthetic_set)))
    labels, milliseconds = Open3DPeer(open3d, PeerParams(voxel_m=0.01, dbscan_eps_m=0.03)
                                      ).segment(points)
    assert labels.shape == frame.depth.shape and labels.dtype == np.int32
    assert (labels[frame.depth == 0] == 0).all()
    assert set(milliseconds) == {"voxel", "plane", "dbscan", "label"}
    plane = labels == 1
    assert plane.sum() > 0.1 * (frame.depth > 0).sum()  # the floor or the wall
    # the plane's pixels lie on one plane, within a few voxels
    on_plane = points[plane]
    centred = on_plane - on_plane.mean(axis=0)
    assert np.linalg.svd(centred, compute_uv=False)[-1] / np.sqrt(len(on_plane)) < 0.02
    assert labels.max() >= 3  # clusters besides the plane


def test_the_report_says_the_peer_was_not_run_without_open3d(
        synthetic_set: Path, small_profile: Path, tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.setitem(sys.modules, "open3d", None)  # `import open3d` raises ImportError
    out = tmp_path / "report"
    data = run_eval(synthetic_set, out, "--params", str(small_profile), "--figures", "1")
    check_report(data, out, ["000000", "000001", "000002"], ["gngdt online"])  # the default
    assert data["peer"]["run"] is False
    assert "open3d cannot be imported" in data["peer"]["status"]
    assert "pip install -e '.[peers]'" in data["peer"]["status"]
    assert "**Peer not run**: open3d cannot be imported" in (out / "segmentation.md").read_text()
    assert "peer not run: open3d cannot be imported" in capsys.readouterr().out


def test_a_missing_label_image_is_named(
        synthetic_set: Path, small_profile: Path, tmp_path: Path, capsys) -> None:
    broken = tmp_path / "broken"
    for kind in ("color", "depth", "label"):
        (broken / kind).mkdir(parents=True)
        for source in sorted((synthetic_set / kind).iterdir()):
            if not (kind == "label" and source.name == "000001.png"):
                os.symlink(source, broken / kind / source.name)
    os.symlink(synthetic_set / "camera.json", broken / "camera.json")
    out = tmp_path / "report"
    assert gngdt(["eval", "segmentation", str(broken), "--out", str(out), "--no-progress",
                  "--params", str(small_profile)]) == 2
    assert "label/000001.png: frame 1: missing ground-truth label image" in capsys.readouterr().err
    assert not out.exists()


def test_report_on_real_labelled_frames(tmp_path: Path) -> None:
    """Two real frames of each labelled set, default profile, the peer if installed."""
    if not LABELLED.is_dir():
        pytest.skip(f"real labelled frames not found at {LABELLED} (the repository's sibling "
                    "../shared)")
    for name in ("mosd_learn", "ycbv_0000"):
        out = tmp_path / name
        data = run_eval(LABELLED / name, out, "--max-frames", "2", "--figures", "1")
        methods = ["gngdt online"] + (["open3d peer"] if HAS_OPEN3D else [])
        check_report(data, out, ["000000", "000001"], methods)
        assert data["intrinsics_from"].endswith("camera.json")
        expected = 0
        for stem in ("000000", "000001"):
            truth = cv2.imread(str(LABELLED / name / "label" / f"{stem}.png"),
                               cv2.IMREAD_UNCHANGED)
            depth = cv2.imread(str(LABELLED / name / "depth" / f"{stem}.png"),
                               cv2.IMREAD_UNCHANGED)
            expected += len(np.unique(truth[(truth >= 2) & (depth > 0)]))
        summary = data["methods"]["gngdt online"]["summary"]
        assert summary["truth_segments"] == expected > 0


def test_the_mug_and_boxes_of_real_frames_come_out_whole(tmp_path: Path) -> None:
    """A floor under the segmentation's quality on ycbv_0000's ten real frames, both modes,
    seed 0: 0.94 mean best IoU and no object fragmented or merged when this was written (5-seed
    means 0.933 / 0.939); the bound leaves room for a seed's worth of variation, not for the
    mug's inside and outside coming apart in half the frames (0.80 did that)."""
    if not LABELLED.is_dir():
        pytest.skip(f"real labelled frames not found at {LABELLED} (the repository's sibling "
                    "../shared)")
    data = run_eval(LABELLED / "ycbv_0000", tmp_path / "ycbv", "--independent", "--online",
                    "--no-peer", "--figures", "0", "--seed", "0")
    for method in ("gngdt independent", "gngdt online"):
        summary = data["methods"][method]["summary"]
        assert summary["truth_segments"] == 30
        assert summary["mean_best_iou"] >= 0.88, method
        assert summary["fragmented"] <= 3 and summary["merged"] <= 3, method
