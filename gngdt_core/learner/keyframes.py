"""Which frame a live learner learns next, of those tracked while it learned the last one.

A live camera sends frames faster than the map can learn them; each is tracked (posed) as it
arrives, and when the learner is free it learns the one that shows the map most that is new: the
farthest from the last learned frame's pose (in metres and in degrees) or the least covered by
the map (the share of its view the alignment found no map for), so that the map is learned from
views spread over where the camera went, not from whichever frame happened to come last. Ties
go to the latest. Pure computation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gngdt.core.kernels import odometry as OK

#: a frame this far from the last learned one (metres) scores 1 ...
KEYFRAME_DISTANCE_M = 0.1
#: ... as does one turned this far from it (degrees) ...
KEYFRAME_TURN_DEG = 10.0
#: ... or one whose view the map covers this much less
KEYFRAME_NOVELTY = 0.2


def keyframe_score(pose: np.ndarray, last_pose: np.ndarray | None, novelty: float) -> float:
    """How much a frame taken at ``pose`` (4, 4) adds to a map last learned from ``last_pose``
    (None: none yet), its view ``novelty`` (0..1) uncovered by the map."""
    score = novelty / KEYFRAME_NOVELTY
    if last_pose is not None:
        moved, turned = OK.motion_size(last_pose, pose)
        score += moved / KEYFRAME_DISTANCE_M + turned / KEYFRAME_TURN_DEG
    return float(score)


def choose_keyframe(poses: Sequence[np.ndarray | None], novelties: Sequence[float],
                    last_pose: np.ndarray | None) -> int | None:
    """Index of the frame to learn among candidates in arrival order (``poses``: each (4, 4),
    None for a frame that has none; ``novelties`` theirs), or None when none has a pose; of
    equal scores the latest."""
    best, best_score = None, -np.inf
    for index, (pose, novelty) in enumerate(zip(poses, novelties, strict=True)):
        if pose is None:
            continue
        score = keyframe_score(pose, last_pose, novelty)
        if score >= best_score:
            best, best_score = index, score
    return best
