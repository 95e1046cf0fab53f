"""Do objects keep their ids? Persistent cluster ids scored frame by frame.

For each clustering, a `ClusterIds` gives every cluster a persistent id and the objects are
the clusters the learner would publish (`gngdt.core.objects.object_set.object_labels`: at least
``min_size`` nodes, seen in ``confirm_frames`` frames in a row). Two figures per clustering:

- ``tracks_kept``: of the objects of one frame, the share whose id is still an object in the
  next. Needs no ground truth.
- with ground-truth labels, ``id_kept`` and ``id_switches``: each ground-truth segment is
  represented in a frame by the object that most of its points fall in (through their winner
  nodes), when that object covers at least half of its points. An id switch is a segment
  represented by a different id than the last time it was represented (the MOT "IDSW");
  ``id_kept`` is the share of such comparisons without a switch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gngdt.core.objects.ids import ClusterIds
from gngdt.core.objects.object_set import object_labels

#: a ground-truth segment needs this many points in a frame to be scored there
MIN_SEGMENT_POINTS = 50


@dataclass
class _ClusteringScore:
    ids: ClusterIds
    previous_objects: set[int] | None = None
    tracks_seen: int = 0
    tracks_kept: int = 0
    last_id: dict[int, int] = field(default_factory=dict)
    comparisons: int = 0
    switches: int = 0


class IdentityScore:
    """Accumulates id persistence over the frames of one replay, per clustering.

    min_size, confirm_frames: which clusters are objects, as the learner's ``min_cluster_size``
    and ``object_confirm_frames``.
    """

    def __init__(self, min_size: int, confirm_frames: int) -> None:
        self.min_size = min_size
        self.confirm_frames = confirm_frames
        self._scores: dict[str, _ClusteringScore] = {}

    def update(self, name: str, node_ids: np.ndarray, node_labels: np.ndarray,
               point_winners: np.ndarray | None = None,
               point_truth: np.ndarray | None = None) -> np.ndarray:
        """Score one frame of clustering ``name``; returns (N,) int64 object id per node (-1: in
        no object).

        node_ids, node_labels: (N,) per node; point_winners: (M,) winner node of each labelled
        point, point_truth: (M,) its ground-truth segment (both None without ground truth).
        """
        score = self._scores.get(name)
        if score is None:
            score = self._scores[name] = _ClusteringScore(
                ClusterIds(confirm_frames=self.confirm_frames))
        cluster_ids = score.ids.update(node_ids, node_labels)
        labels = object_labels(node_labels, score.ids.confirmed_, self.min_size)
        node_objects = np.where(labels >= 0, cluster_ids[np.maximum(labels, 0)]
                                if len(cluster_ids) else -1, -1)
        present = set(np.unique(node_objects[node_objects >= 0]).tolist())
        if score.previous_objects is not None:
            score.tracks_seen += len(score.previous_objects)
            score.tracks_kept += len(score.previous_objects & present)
        score.previous_objects = present
        if point_winners is not None and point_truth is not None:
            self._score_segments(score, node_objects[point_winners], point_truth)
        return node_objects

    @staticmethod
    def _score_segments(score: _ClusteringScore, point_objects: np.ndarray,
                        truth: np.ndarray) -> None:
        for segment in np.unique(truth):
            objects = point_objects[truth == segment]
            if objects.size < MIN_SEGMENT_POINTS:
                continue
            ids, counts = np.unique(objects, return_counts=True)
            best = int(np.argmax(np.where(ids >= 0, counts, -1)))
            if ids[best] < 0 or counts[best] < 0.5 * objects.size:
                continue  # no object covers most of the segment in this frame
            represented = int(ids[best])
            last = score.last_id.get(int(segment))
            if last is not None:
                score.comparisons += 1
                score.switches += represented != last
            score.last_id[int(segment)] = represented

    def summary(self) -> dict[str, dict[str, float | int | None]]:
        """Per clustering: tracks_kept (share), and id_kept (share), id_switches, comparisons
        (None / 0 without ground truth)."""
        result = {}
        for name, score in self._scores.items():
            result[name] = {
                "tracks_kept": (score.tracks_kept / score.tracks_seen
                                if score.tracks_seen else None),
                "id_kept": (1.0 - score.switches / score.comparisons
                            if score.comparisons else None),
                "id_switches": score.switches,
                "id_comparisons": score.comparisons,
            }
        return result
