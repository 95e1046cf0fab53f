"""Persistent cluster ids (ClusterIds) and objects (describe_objects, ObjectFinder)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gngdt.core import GNGDT
from gngdt.core.objects.ids import ClusterIds
from gngdt.core.objects.object_set import ObjectFinder, describe_objects, drop_small, object_labels
from gngdt.eval.synthetic import make_data2


def _ids_of(cluster_ids: ClusterIds, node_ids, labels) -> dict[int, int]:
    """{first node id of each cluster: its persistent id}."""
    ids = cluster_ids.update(np.asarray(node_ids), np.asarray(labels))
    labels = np.asarray(labels)
    return {int(np.asarray(node_ids)[labels == k][0]): int(ids[k]) for k in range(len(ids))}


def test_relabelled_clusters_keep_their_ids():
    cluster_ids = ClusterIds()
    nodes = np.arange(100, 130)
    first = _ids_of(cluster_ids, nodes, np.repeat([0, 1, 2], 10))
    # the same clusters numbered the other way round, nodes listed in another order, new nodes
    nodes2 = np.concatenate([nodes[::-1], [500, 501]])
    labels2 = np.concatenate([np.repeat([0, 1, 2], 10), [0, 1]])
    ids2 = cluster_ids.update(nodes2, labels2)
    assert {int(ids2[0]), int(ids2[1]), int(ids2[2])} == set(first.values())
    assert int(ids2[0]) == first[120] and int(ids2[2]) == first[100]


def test_split_merge_and_return_within_memory():
    cluster_ids = ClusterIds(memory_frames=3)
    nodes = np.arange(40)
    ids = cluster_ids.update(nodes, np.repeat([0, 1], [30, 10]))
    big, small = int(ids[0]), int(ids[1])
    # split of the big cluster: the part with most of its nodes keeps the id, the other is new
    ids = cluster_ids.update(nodes, np.repeat([0, 1, 2], [20, 10, 10]))
    assert int(ids[0]) == big and int(ids[2]) == small and int(ids[1]) not in (big, small)
    split_off = int(ids[1])
    # merge back: the merged cluster keeps the larger contributor's id
    ids = cluster_ids.update(nodes, np.repeat([0, 1], [30, 10]))
    assert int(ids[0]) == big and int(ids[1]) == small
    # the small cluster vanishes (below min size: -1) for two labellings, then comes back
    for _ in range(2):
        cluster_ids.update(nodes, np.repeat([0, -1], [30, 10]))
    assert int(cluster_ids.update(nodes, np.repeat([0, 1], [30, 10]))[1]) == small
    # after more than memory_frames labellings a vanished cluster is forgotten
    for _ in range(3):
        cluster_ids.update(nodes, np.repeat([0, -1], [30, 10]))
    new = int(cluster_ids.update(nodes, np.repeat([0, 1], [30, 10]))[1])
    assert new not in (big, small, split_off)


def test_a_cluster_made_mostly_of_a_taken_cluster_gets_a_new_id():
    cluster_ids = ClusterIds(min_overlap=0.5)
    a, b = cluster_ids.update(np.arange(30), np.repeat([0, 1], [20, 10])).tolist()
    # A (nodes 0-19) splits 12/8; the 8 join 3 nodes of B; B's other 7 nodes stay together
    labels = np.repeat([0, 1, 2], [12, 11, 7])
    ids = cluster_ids.update(np.arange(30), labels).tolist()
    assert ids[0] == a  # most of A
    assert ids[1] not in (a, b)  # A is taken and B holds only 3 of its 11 nodes (< 0.5)
    assert ids[2] == b  # the rest of B, 7 of 7


def test_a_cluster_is_confirmed_after_confirm_frames_in_a_row_and_stays_confirmed():
    cluster_ids = ClusterIds(confirm_frames=3, memory_frames=10)
    nodes = np.arange(40)
    both, big_only = np.repeat([0, 1], [30, 10]), np.repeat([0, -1], [30, 10])
    seen = []
    # the small cluster flickers (seen, gone, seen, seen, seen); the big one is always there
    for labels in (both, big_only, both, both, both):
        cluster_ids.update(nodes, labels)
        seen.append(cluster_ids.confirmed_.tolist())
    assert [frame[0] for frame in seen] == [False, False, True, True, True]
    assert [frame[1] for frame in seen[2:]] == [False, False, True]  # the streak starts again
    # confirmed for good while remembered: gone for a while, back at once as confirmed
    for _ in range(4):
        cluster_ids.update(nodes, big_only)
    cluster_ids.update(nodes, both)
    assert cluster_ids.confirmed_.tolist() == [True, True]
    assert ClusterIds().update(nodes, both).tolist() == [0, 1]  # default: confirmed at once
    with pytest.raises(ValueError, match="confirm_frames"):
        ClusterIds(confirm_frames=0)


def test_a_confirmed_cluster_keeps_its_id_when_a_larger_fresh_fragment_merges_back():
    cluster_ids = ClusterIds(confirm_frames=3)
    for _ in range(3):
        (object_id,) = cluster_ids.update(np.arange(20), np.zeros(20, dtype=int)).tolist()
    assert cluster_ids.confirmed_.tolist() == [True]
    # the network grows: 8 of its nodes and 10 new ones split off (a new, unconfirmed id) ...
    nodes = np.arange(30) + np.repeat([0, 80], [20, 10])
    ids = cluster_ids.update(nodes, np.repeat([0, 1], [12, 18])).tolist()
    assert ids[0] == object_id and ids[1] != object_id
    assert cluster_ids.confirmed_.tolist() == [True, False]
    # ... and merge back: the fragment brought more nodes, the object keeps its id and status
    ids = cluster_ids.update(nodes, np.zeros(30, dtype=int)).tolist()
    assert ids == [object_id]
    assert cluster_ids.confirmed_.tolist() == [True]


def test_object_labels_keep_confirmed_clusters_of_min_size_only():
    labels = np.array([0, 0, 0, 1, 1, 1, 2, -1])
    assert object_labels(labels, np.array([True, False, True]), 2).tolist() == [
        0, 0, 0, -1, -1, -1, -1, -1]  # 1 is not confirmed, 2 is too small
    assert object_labels(np.full(3, -1), np.zeros(0, bool), 2).tolist() == [-1, -1, -1]
    with pytest.raises(ValueError, match="confirmed"):
        object_labels(labels, np.array([True]), 1)


def test_many_clusters_stay_within_max_tracks():
    cluster_ids = ClusterIds(max_tracks=50, memory_frames=1000)
    rng = np.random.default_rng(0)
    for frame in range(20):  # 200 fresh clusters a frame, nothing ever persists
        node_ids = np.arange(frame * 2000, frame * 2000 + 2000)
        cluster_ids.update(node_ids, rng.integers(0, 200, node_ids.size))
        assert cluster_ids.n_tracks_ <= 50


def test_tracker_validates_its_inputs():
    with pytest.raises(ValueError, match="min_overlap"):
        ClusterIds(min_overlap=0)
    with pytest.raises(ValueError, match="memory_frames"):
        ClusterIds(memory_frames=0)
    with pytest.raises(ValueError, match="equal-length"):
        ClusterIds().update(np.arange(3), np.zeros(4, int))
    assert ClusterIds().update(np.zeros(0, np.int64), np.zeros(0, int)).shape == (0,)


def test_describe_objects_recovers_an_oriented_box_colour_and_normal():
    rng = np.random.default_rng(1)
    rotation = Rotation.from_euler("xyz", [20, -35, 60], degrees=True).as_matrix()
    half = np.array([0.30, 0.10, 0.02])  # a flat slab: its normal is the third axis
    corners = rng.uniform(-1, 1, (4000, 3)) * half
    box_points = corners @ rotation.T + [1.0, 2.0, 3.0]
    other = rng.normal(size=(50, 3)) * 0.01 + [5.0, 5.0, 5.0]
    positions = np.vstack([box_points, other])
    labels = np.repeat([1, 0], [4000, 50])  # label 1 = the box
    colors = np.vstack([np.full((4000, 3), [200.0, 10.0, 30.0]), np.zeros((50, 3))])
    slab_normal = rotation[:, 2]
    normals = np.vstack([np.tile(slab_normal, (4000, 1)), np.zeros((50, 3))])
    normals[:1000] *= -1  # a quarter face the other way: the majority decides the sign
    normals[1000:1100] = 0.0  # undefined normals are ignored
    objects = describe_objects(positions, colors, normals, labels, ids=np.array([7, 42]))
    assert len(objects) == 2 and objects.ids.tolist() == [7, 42]
    box = 1
    assert objects.node_counts[box] == 4000
    np.testing.assert_allclose(objects.centroids[box], [1.0, 2.0, 3.0], atol=0.01)
    np.testing.assert_allclose(objects.centers[box], [1.0, 2.0, 3.0], atol=0.01)
    np.testing.assert_allclose(objects.sizes[box], 2 * half, rtol=0.02)
    # the box axes are the slab's axes up to sign; rotations are proper
    np.testing.assert_allclose(np.abs(objects.rotations[box].T @ rotation), np.eye(3), atol=0.02)
    np.testing.assert_allclose(np.linalg.det(objects.rotations), 1.0)
    np.testing.assert_allclose(objects.colors[box], [200, 10, 30])
    np.testing.assert_allclose(objects.normals[box], slab_normal, atol=1e-9)
    assert not objects.normals[0].any()  # no defined normal: zeros
    quaternions = objects.quaternions_xyzw
    np.testing.assert_allclose(Rotation.from_quat(quaternions).as_matrix(), objects.rotations,
                               atol=1e-9)
    # every point lies inside its box
    local = (box_points - objects.centers[box]) @ objects.rotations[box]
    assert np.all(np.abs(local) <= objects.sizes[box] / 2 + 1e-9)


def test_describe_objects_skips_empty_labels_and_validates():
    positions = np.zeros((3, 3))
    objects = describe_objects(positions, None, None, np.array([2, 2, -1]))
    assert objects.ids.tolist() == [2] and objects.node_counts.tolist() == [2]
    assert len(describe_objects(positions, None, None, np.full(3, -1))) == 0
    with pytest.raises(ValueError, match="ids"):
        describe_objects(positions, None, None, np.array([0, 1, 1]), ids=np.array([5]))


def test_objects_of_a_static_scene_keep_their_ids_frame_to_frame():
    positions, colors, _ = make_data2(n_points=20_000, random_state=0)
    model = GNGDT(max_nodes=300, random_state=0)
    finder = ObjectFinder("col+nor", min_size=5, confirm_frames=3)
    model.partial_fit(positions, colors, n_steps=200_000)  # grown: the frames refine it
    assert len(finder.update(model)) == 0  # no cluster is confirmed yet
    finder.update(model)
    previous = set(finder.update(model).ids.tolist())  # seen 3 times in a row: objects
    kept = total = 0
    rng = np.random.default_rng(0)
    for _ in range(20):  # a static scene seen frame after frame: new samples of the same points
        frame = rng.choice(len(positions), 5_000, replace=False)
        model.partial_fit(positions[frame], colors[frame], n_steps=5_000)
        objects = finder.update(model)
        current = set(objects.ids[objects.node_counts >= 10].tolist())
        kept += len(previous & set(objects.ids.tolist()))
        total += len(previous)
        previous = current
    assert total >= 20 * 3
    assert kept / total >= 0.95, (kept, total)


def test_drop_small_sets_small_clusters_to_none_even_when_none_is_left() -> None:
    labels = np.array([0, 0, 0, 1, -1, 2, 2])
    assert drop_small(labels, 2).tolist() == [0, 0, 0, -1, -1, 2, 2]
    assert drop_small(np.array([-1, -1]), 2).tolist() == [-1, -1]  # a segmentation of fragments
