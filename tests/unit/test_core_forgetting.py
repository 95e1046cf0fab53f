"""World-frame learning (``camera_pose``) and forgetting (GNG-U utility, judged only in view),
on virtual Kinect frames of scenes that move."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.forgetting_scenes import FORGETTING, HEIGHT, PARAMS, STEPS, WIDTH, frames_of, to_world
from scipy.spatial import cKDTree

from gngdt.core import GNGDT
from gngdt.core.metrics import ghost_nodes
from gngdt.core.sensor.view import seen_nodes
from gngdt.eval.synthetic import make_data2
from gngdt.io.deproject import Deprojector
from gngdt.io.synth.render import render_scene


def ids_of(segments: dict[int, str], primitive: str) -> list[int]:
    return [i for i, name in segments.items() if name.split("/")[0] == primitive]


def test_with_poses_the_network_is_a_map_in_the_fixed_frame():
    """The walking camera moves 3.2 m sideways: with its poses the network holds the crate seen
    at the start and the bin seen at the end at their places in the world, and its normals face
    the camera's latest position; learned in the camera frame, the crate is gone."""
    frames = list(frames_of("tabletop_walk", 25, fps=6.0))  # 4 s: one way along the walk
    mapped = GNGDT(**PARAMS)
    camera = GNGDT(**PARAMS)
    for points, colors, pose, _, _ in frames:
        mapped.partial_fit(points, colors, n_steps=STEPS, camera_pose=pose)
        camera.partial_fit(points, colors, n_steps=STEPS)

    def surface(index: int, primitive: str) -> np.ndarray:
        points, _, pose, labels, segments = frames[index]
        return to_world(points[np.isin(labels, ids_of(segments, primitive))], pose)

    def nodes_on(nodes: np.ndarray, world: np.ndarray) -> int:
        return int(np.sum(cKDTree(world).query(nodes)[0] <= 0.05))

    crate, bin_ = surface(0, "crate"), surface(-1, "bin")
    assert nodes_on(mapped.positions_, crate) >= 5 and nodes_on(mapped.positions_, bin_) >= 5
    last_pose = frames[-1][2]
    camera_in_world = to_world(camera.positions_, last_pose)
    assert nodes_on(camera_in_world, crate) <= 1
    normals, positions = mapped.normals_, mapped.positions_
    points, pose = frames[-1][0], frames[-1][2]
    defined = np.linalg.norm(normals, axis=1) > 0
    towards = np.einsum("ij,ij->i", normals, pose[:3, 3] - positions)
    seen = seen_nodes(positions, points, pose)
    assert (defined & seen).sum() > 50 and np.all(towards[defined & seen] >= 0)


def test_camera_pose_is_validated():
    model = GNGDT(**PARAMS)
    points = np.random.default_rng(0).random((100, 3)) + np.array([0.0, 0.0, 1.0])
    squashed = np.diag([1.0, 2.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="rigid"):
        model.partial_fit(points, camera_pose=squashed)
    with pytest.raises(ValueError, match=r"\(4, 4\)"):
        model.partial_fit(points, camera_pose=np.eye(3))
    with pytest.raises(ValueError, match="3-D"):
        model.partial_fit(points[:, :2], camera_pose=np.eye(4))
    # 0 = off, as None (TOML has no None)
    assert GNGDT(utility_k=0).check_params()["utility_k"] is None
    for bad in ({"utility_k": -1.0}, {"utility_decay": 1.0},
                {"view_depth_margin": -0.1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            GNGDT(**bad).check_params()


def old_place_nodes(model: GNGDT, old_place: np.ndarray, frame: cKDTree) -> int:
    """Nodes within 5 cm of where the object was and farther than that from the frame."""
    nodes = model.positions_
    near_old = cKDTree(old_place).query(nodes)[0] <= 0.05
    stale = frame.query(nodes)[0] > 0.05
    return int(np.sum(near_old & stale))


def test_a_vanished_object_is_forgotten_within_30_frames_and_only_with_forgetting():
    """tabletop_vanish at 30 fps with the learner's budget and steps: the network is full at
    frame 50, the red box vanishes at frame 60. With forgetting its old place is empty within
    30 frames for good, also while rehearsing earlier frames (the learner's profile: the box's
    remembered samples go as soon as the sensor sees through them); without, nodes stay there."""
    params = {"max_nodes": 1000, "lambda_": 500, "random_state": 0}
    forgetting, paper = GNGDT(**params, **FORGETTING), GNGDT(**params)
    profile = GNGDT(**params, **FORGETTING, replay_share=0.3)
    counts: dict[str, list[int]] = {"forgetting": [], "profile": [], "paper": []}
    old_place = None
    deproject = Deprojector()
    for index, frame in enumerate(render_scene("tabletop_vanish", 91, width=WIDTH,
                                               height=HEIGHT)):
        points, colors = deproject(frame.depth, frame.color, frame.intrinsics)
        pose = frame.pose.matrix
        world = to_world(points, pose)
        if old_place is not None:
            frame_tree = cKDTree(world)
        if index == 59:
            from gngdt.eval.recording_eval import deproject_labels

            labels = deproject_labels(deproject, frame.depth, frame.labels, frame.intrinsics)
            old_place = world[np.isin(labels, ids_of(frame.extras["segments"], "red_box"))]
        for name, model in (("forgetting", forgetting), ("profile", profile), ("paper", paper)):
            model.partial_fit(points, colors, n_steps=STEPS, camera_pose=pose)
            if old_place is not None and index >= 60:
                counts[name].append(old_place_nodes(model, old_place, frame_tree))
    assert counts["forgetting"][0] > 0 and counts["paper"][0] > 0  # the box was learned
    for name in ("forgetting", "profile"):
        assert counts[name][0] > 0, counts
        gone_after = counts[name].index(0)
        assert gone_after <= 30 and max(counts[name][gone_after:]) == 0, counts
    assert min(counts["paper"]) > 0, counts  # without forgetting some stay for good
    assert forgetting.n_nodes_ <= params["max_nodes"] and forgetting.n_forgotten_ > 0


def test_out_of_view_nodes_are_kept_and_their_utility_frozen():
    """The walk: the crate is in view at the start and out of view at the far end; its nodes
    stay, unmoved, with the utility they had when it left the view."""
    fps = 5.0  # 20 frames one way
    model = GNGDT(**PARAMS, **FORGETTING)
    frames = list(frames_of("tabletop_walk", 21, fps))
    first_points, _, first_pose, first_labels, segments = frames[0]
    crate = to_world(first_points[np.isin(first_labels, ids_of(segments, "crate"))], first_pose)
    crate_nodes, utilities, positions, ids = [], None, None, None
    for index, (points, colors, pose, _, _) in enumerate(frames):
        model.partial_fit(points, colors, n_steps=STEPS, camera_pose=pose)
        on_crate = cKDTree(crate).query(model.positions_)[0] <= 0.05
        crate_nodes.append(int(on_crate.sum()))
        seen = seen_nodes(model.positions_, points, pose)
        if index == 14:  # the crate has left the view: remember its nodes
            assert not seen[on_crate].any()
            ids = model.node_ids_[on_crate]
            utilities = model.utilities_[on_crate]
            positions = model.positions_[on_crate]
    assert crate_nodes[6] >= 5
    assert crate_nodes[-1] >= crate_nodes[14] > 0.7 * max(crate_nodes)
    still = np.isin(model.node_ids_, ids)
    order = np.argsort(model.node_ids_[still])
    assert still.sum() == len(ids)  # every crate node survived the rest of the walk
    np.testing.assert_array_equal(model.positions_[still][order], positions[np.argsort(ids)])
    np.testing.assert_allclose(model.utilities_[still][order], utilities[np.argsort(ids)],
                               rtol=1e-9)


def test_ghost_nodes_are_those_seen_where_nothing_is():
    """A network learned on a wall at z = 2 with a box in front; the box removed, its nodes are
    seen (in front of the wall) and farther than 5 cm from the wall: ghosts. Nodes behind the
    wall or outside the view are not seen."""
    rng = np.random.default_rng(1)
    wall = np.column_stack([rng.uniform(-0.8, 0.8, 20_000), rng.uniform(-0.6, 0.6, 20_000),
                            np.full(20_000, 2.0)])
    nodes = np.array([
        [0.0, 0.0, 1.5],    # in front of the wall, in the middle: a ghost
        [0.1, 0.1, 2.0],    # on the wall: seen, not a ghost
        [0.0, 0.0, 2.6],    # behind the wall: occluded, not seen
        [3.0, 0.0, 2.0],    # outside the view
        [0.2, -0.1, 2.03],  # on the wall within the depth margin: seen
    ])
    seen, ghost = ghost_nodes(nodes, wall, None, distance=0.05, margin=0.05)
    assert seen.tolist() == [True, True, False, False, True]
    assert ghost.tolist() == [True, False, False, False, False]
    # the same in a world frame the camera is moved into
    pose = np.eye(4)
    pose[:3, 3] = [5.0, -1.0, 0.5]
    seen_w, ghost_w = ghost_nodes(nodes + pose[:3, 3], wall, pose, 0.05, 0.05)
    assert seen_w.tolist() == seen.tolist() and ghost_w.tolist() == ghost.tolist()


def test_forgetting_off_leaves_the_paper_algorithm_untouched():
    """utility_k None: the same network as before forgetting existed, whatever the margin."""
    positions, colors, _ = make_data2(n_points=5_000, random_state=0)
    plain = GNGDT(max_nodes=80, lambda_=100, random_state=4).fit(positions, colors, 20_000)
    other = GNGDT(max_nodes=80, lambda_=100, random_state=4, view_depth_margin=0.5,
                  utility_decay=0.01).fit(positions, colors, 20_000)
    np.testing.assert_array_equal(plain.positions_, other.positions_)
    np.testing.assert_array_equal(plain.edges("nor"), other.edges("nor"))
    assert plain.n_forgotten_ == 0 and not plain.judged_.any()
