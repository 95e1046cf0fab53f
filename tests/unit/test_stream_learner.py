"""Learning a stream of frames (gngdt.core.learner.stream_learner), the sensor profile, veil
points."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from gngdt.core.gas import queries
from gngdt.core.learner.frame_learner import FrameLearner
from gngdt.core.learner.frame_segmenter import FrameSegmenter, veil_pixels
from gngdt.core.learner.stream_learner import FrameSchedule, StreamLearner
from gngdt.io.deproject import Deprojector
from gngdt.io.mcap.reader import read_frames
from gngdt.io.profiles import load_profile
from gngdt.services.capture import CloudOptions, FrameToCloud

ROOT = Path(__file__).resolve().parents[2]
PROFILE = ROOT / "config" / "kinect.toml"
#: a small network and few steps: what the schedule decides, not how well it learns
QUICK = {"max_nodes": 300, "lambda_": 50}
QUICK_SCHEDULE = FrameSchedule(steps_first_frame=15_000, steps_per_frame=3_000)


def frame_clouds(name: str, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    deproject = Deprojector()
    clouds = []
    for frame in read_frames(ROOT / "recordings" / name):
        clouds.append(deproject(frame.depth, frame.color, frame.intrinsics))
        if len(clouds) == count:
            break
    return clouds


def test_a_stream_carries_its_network_and_starts_over_on_a_new_scene() -> None:
    tabletop = frame_clouds("tabletop_small.mcap", 3)
    data2 = frame_clouds("data2.mcap", 1)
    stream = StreamLearner(QUICK, schedule=QUICK_SCHEDULE, random_state=0)
    learned = [stream.learn_frame(*cloud) for cloud in [*tabletop, *data2]]
    assert [frame.from_scratch for frame in learned] == [True, False, False, True]
    assert [frame.steps for frame in learned] == [15_000, 3_000, 3_000, 15_000]
    assert learned[-1].segmentation.labels.size == stream.model_.n_nodes_


def tabletop_points_on_objects() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first tabletop frame's valid points (N, 3), colours (N, 3) and (N,) bool: on an
    object (the floor, the wall and the table top each cover > 5 % of the image; the rest is
    objects)."""
    frame = next(iter(read_frames(ROOT / "recordings" / "tabletop.mcap")))
    points = Deprojector().organized(frame.depth, frame.intrinsics).reshape(-1, 3)
    valid = np.isfinite(points[:, 2])
    truth = frame.labels.reshape(-1)[valid]
    on_object = (np.bincount(truth) < 0.05 * truth.size)[truth]
    return points[valid], frame.color.reshape(-1, 3)[valid], on_object


def test_attention_moves_nodes_from_the_large_surfaces_to_the_objects() -> None:
    positions, colors, on_object = tabletop_points_on_objects()

    def node_share_on_objects(share: float) -> float:
        # attention acts on the nodes still to grow: most of the budget is left after warm-up
        schedule = FrameSchedule(steps_first_frame=60_000, flat_surface_share=share,
                                 warm_up_share=0.15)
        stream = StreamLearner({"max_nodes": 600, "lambda_": 50}, schedule=schedule,
                               random_state=1)
        stream.learn_frame(positions, colors)
        nearest_point = cKDTree(positions).query(stream.model_.positions_)[1]
        return float(np.mean(on_object[nearest_point]))

    assert node_share_on_objects(0.05) > 1.3 * node_share_on_objects(1.0)


def test_attention_follows_the_prior_an_earlier_frame_gives() -> None:
    positions, colors, on_object = tabletop_points_on_objects()

    def node_share_on_objects(prior: np.ndarray) -> float:
        schedule = FrameSchedule(steps_first_frame=30_000, steps_per_frame=30_000)
        stream = StreamLearner({"max_nodes": 400, "lambda_": 50}, schedule=schedule,
                               random_state=1)
        stream.learn_frame(positions, colors)
        for _ in range(4):  # the same view again: the carried network, thinned by the prior
            assert not stream.learn_frame(positions, colors, on_large_surface=prior).from_scratch
        nearest_point = cKDTree(positions).query(stream.model_.positions_)[1]
        return float(np.mean(on_object[nearest_point]))

    # a prior that calls the objects the large surfaces takes nodes off them (ignoring the
    # prior, both runs would be the same)
    assert node_share_on_objects(on_object) < 0.8 * node_share_on_objects(~on_object)
    with pytest.raises(ValueError, match="on_large_surface"):
        StreamLearner(QUICK, schedule=QUICK_SCHEDULE).learn_frame(
            positions, colors, on_large_surface=on_object[:-1])


def test_frame_segmenter_labels_the_valid_pixels_of_an_organized_frame() -> None:
    frame = next(iter(read_frames(ROOT / "recordings" / "tabletop_small.mcap")))
    points = Deprojector().organized(frame.depth, frame.intrinsics)
    segmenter = FrameSegmenter(QUICK, schedule=QUICK_SCHEDULE, random_state=0)
    result = segmenter.segment_frame(points, frame.color)
    valid = np.isfinite(points[..., 2])
    assert result.labels.shape == frame.depth.shape
    assert (result.labels[~valid] == 0).all()
    assert np.mean(result.labels[valid] == 0) < 0.05  # only nodes of no segment
    assert result.labels.max() == result.n_segments
    assert result.from_scratch and result.steps == 15_000


def test_pixel_labels_are_the_nearest_nodes_labels_but_where_a_region_is_a_pixel_thin() -> None:
    frame = next(iter(read_frames(ROOT / "recordings" / "tabletop_small.mcap")))
    points = Deprojector().organized(frame.depth, frame.intrinsics)
    valid = np.isfinite(points[..., 2])
    stream = StreamLearner(QUICK, schedule=QUICK_SCHEDULE, random_state=0)
    stream.learn_frame(points[valid], frame.color[valid])
    model = stream.model_
    anchors = np.zeros_like(valid)
    stride = queries.LABEL_ANCHOR_STRIDE
    anchors[::stride, ::stride] = True

    def labels_and_exact(node_labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        exact = np.zeros(valid.shape, dtype=np.int64)
        exact[valid] = node_labels[model.predict(points[valid])] + 1
        return model.label_pixels(points, node_labels), exact

    # every node its own label (Voronoi cells, corners poking between anchors: the worst case),
    # then the segments (what it is for)
    every_node = np.arange(model.n_nodes_, dtype=np.int32)
    every_node[::7] = -1
    for node_labels, tolerance in ((every_node, 0.01), (model.segment(), 0.001)):
        labels, exact = labels_and_exact(node_labels)
        assert labels.shape == valid.shape and (labels[~valid] == 0).all()
        assert (labels[anchors] == exact[anchors]).all()
        assert np.mean(labels[valid] != exact[valid]) < tolerance
    with pytest.raises(ValueError, match="node_labels"):
        model.label_pixels(points, every_node[:-1])


def test_veil_pixels_are_the_two_sides_of_a_depth_jump() -> None:
    depth = np.full((6, 8), 1000, dtype=np.uint16)
    depth[:, 4:] = 1500  # a 50 cm jump between columns 3 and 4
    depth[0, 0] = 0      # no measurement: never a veil point
    depth[5, 1] = 1010   # 1 %: noise, not a jump
    veil = veil_pixels(depth, 0.03)
    expected = np.zeros_like(veil)
    expected[:, 3:5] = True
    assert np.array_equal(veil, expected)


def test_capture_drops_veil_points_when_asked() -> None:
    frame = next(iter(read_frames(ROOT / "recordings" / "tabletop_small.mcap")))
    every = FrameToCloud(CloudOptions())(frame)[0]
    without_veil = FrameToCloud(CloudOptions(veil_ratio=0.03))(frame)[0]
    veil = veil_pixels(frame.depth, 0.03) & (frame.depth > 0)
    assert 0 < len(every) - len(without_veil) == np.count_nonzero(veil)


def test_the_learner_learns_and_segments_through_the_sensor_profile() -> None:
    config = load_profile(PROFILE).config
    assert config.schedule is not None and config.model["max_nodes"] == 4000
    config = replace(config, model={**config.model, **QUICK},
                     options=replace(config.options, samples_per_frame=3_000),
                     schedule=replace(config.schedule, steps_first_frame=15_000))
    learner = FrameLearner("camera", config)
    for positions, colors in frame_clouds("tabletop_small.mcap", 2):
        learner.learn(positions, colors)
    assert learner.counters.learning_steps == 18_000
    assert learner.model is learner.stream.model_
    segments = learner.last_segmentation.labels
    assert segments.size == learner.model.n_nodes_ and segments.max() >= 1


def test_a_profile_with_a_wrong_frames_key_names_it(tmp_path: Path) -> None:
    path = tmp_path / "profile.toml"
    path.write_text("[frames]\nsteps_per_franme = 10\n")
    with pytest.raises(ValueError, match="steps_per_franme"):
        load_profile(path)


@pytest.mark.parametrize(("settle_max_steps", "settled_steps"), [
    (30_000, 10_000),  # never more than a normal frame's share (samples_per_frame) ...
    (4_000, 4_000),  # ... nor than settle_max_steps
])
def test_settling_stops_at_its_step_limit_and_says_so(settle_max_steps: int,
                                                      settled_steps: int) -> None:
    config = load_profile(None).config
    config = replace(config, model={**config.model, "max_nodes": 5000},  # a budget it cannot
                     options=replace(config.options, samples_per_frame=10_000,  # reach in time
                                     settle_max_steps=settle_max_steps))
    learner = FrameLearner("camera", config)
    positions, colors = frame_clouds("tabletop_small.mcap", 1)[0]
    learner.learn(positions, colors)
    reason = learner.settle(positions, colors)
    assert reason.startswith(f"stopped after {settled_steps:,} more steps"), reason
    assert learner.model.n_steps_ == 10_000 + settled_steps
