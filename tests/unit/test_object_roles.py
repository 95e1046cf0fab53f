"""Segment roles reach the published objects: each object says whether it is an object, a
support or clutter (issue 26, item 4), in the learner's `ObjectSet` and on the wire."""

from __future__ import annotations

import numpy as np
from helpers.segmentation_scenes import (
    TABLE_Y,
    box,
    majority,
    network,
    segment,
    table,
    table_wall_and_box,
)

from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig, LearnerOptions
from gngdt.core.objects.object_set import describe_objects
from gngdt.core.segmentation.supports import OBJECT, ROLE_NAMES, SUPPORT
from gngdt.schemas.scene import decode_object_boxes, objects_to_scene_update


def scene_update_of(objects) -> bytes:
    return objects_to_scene_update(
        ids=objects.ids, centers=objects.centers, quaternions_xyzw=objects.quaternions_xyzw,
        sizes=objects.sizes, colors=np.zeros((len(objects), 3), np.uint8),
        node_counts=objects.node_counts, centroids=objects.centroids,
        mean_colors=objects.colors, normals=objects.normals, timestamp_ns=1, frame_id="camera",
        roles=[ROLE_NAMES[role] for role in objects.roles]).SerializeToString()


def test_a_table_and_a_wall_are_published_as_supports_and_the_box_as_an_object() -> None:
    positions, normals, edges, part = network(table_wall_and_box(np.random.default_rng(0)))
    result = segment(positions, normals, edges)
    objects = describe_objects(positions, None, normals, result.labels, roles=result.roles)
    segments = [majority(result.labels, part, which)[0] for which in range(3)]
    assert [objects.roles[list(objects.ids).index(s)] for s in segments] == \
        [SUPPORT, SUPPORT, OBJECT]

    boxes = decode_object_boxes(scene_update_of(objects))
    by_id = dict(zip(boxes.ids.tolist(), zip(boxes.roles, boxes.labels, strict=True),
                     strict=True))
    table_id, wall_id, box_id = (int(objects.ids[list(objects.ids).index(s)]) for s in segments)
    assert by_id[table_id] == ("support", f"#{table_id} support")
    assert by_id[wall_id][0] == "support"
    assert by_id[box_id] == ("object", f"#{box_id}")


def test_the_learner_judges_roles_only_for_segments() -> None:
    rng = np.random.default_rng(1)
    positions = np.vstack([table(rng)[0], box(rng, (-0.05, 0.05), TABLE_Y, 0.1, (0.8, 0.9))[0]])
    colors = np.full((len(positions), 3), 128, np.uint8)
    for objects_from in ("segments", "pos"):
        options = LearnerOptions(samples_per_frame=30_000, objects_from=objects_from,
                                 min_cluster_size=3)
        learner = FrameLearner("camera", LearnerConfig(options=options))
        learner.learn(positions.astype(np.float32), colors)
        learned = learner.learned_frame()
        objects = learner.objects(learned, final=True)
        assert len(objects) > 0
        if objects_from == "pos":
            assert learned.segment_roles is None
            assert (objects.roles == OBJECT).all()
            continue
        # each object's role is its segment's (found by the object's persistent id)
        labels = learned.labels["segments"]
        ids = learned.cluster_ids["segments"]
        for object_id, role in zip(objects.ids, objects.roles, strict=True):
            segment_label = int(np.flatnonzero(ids == object_id)[0])
            assert (labels == segment_label).any()
            assert role == learned.segment_roles[segment_label]
        assert SUPPORT in objects.roles  # the table
