"""Where to start aligning a frame when the prediction is in doubt (`MapOdometry.track`).

In order, once the alignment from the prediction failed: the last tracked pose (the camera may have
stopped); a start searched around the prediction (`searched_start`: moved by up to ``search_steps``
coarse gates along each camera axis, or turned about its x and y axes: the camera may be farther
on, or turned); then, relocalising against the whole map (`relocalisation_starts`): the last motion
continued over the whole time since the last tracked frame and to a few distances (a camera that
went on while it was not tracked, past ``coast_s``, at its pace or another) and the poses the map
was learned from (`MapOdometry.keyframes`, spread over the map: a camera that came back to a place
it has been). Each candidate is aligned on the coarse level only, with at most `SEARCH_ITERATIONS`
Gauss-Newton steps; the one that agrees with the most of the frame (overlap times inlier share)
wins. Pure computation.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from typing import Any, Protocol

import numpy as np

from gngdt.core.kernels import odometry as OK
from gngdt.core.odometry.map_surface import MapSurface


class MapOdometry(Protocol):
    """What the starts are found with: `gngdt.core.odometry.map_odometry.MapOdometry`."""

    params: Any
    pose_: np.ndarray | None
    velocity_: np.ndarray
    motion_span_s_: float
    keyframes: Sequence[np.ndarray]

    def seconds_since(self, stamp_ns: int | None) -> float: ...

    def align(self, levels: list[tuple], surface: MapSurface, start: np.ndarray,
              max_steps: int | None = None) -> tuple[np.ndarray, str, dict[str, Any]]: ...

#: a searched start replaces the prediction when its coarse alignment agrees with this much
#: more of the frame (overlap times inlier share): a repetitive scene's near-tie keeps the
#: prediction
SEARCH_MARGIN = 0.05
#: Gauss-Newton steps of a searched start's coarse alignment at most (the level's own: 8):
#: enough to tell the starts apart, at half the cost
SEARCH_ITERATIONS = 4
#: shares of the time since the last tracked frame the last motion is continued over, when
#: relocalising ...
GAP_SHARES = (0.5, 1.0, 1.5)
#: ... and distances (metres) it is continued to, its turn in proportion (a camera that went on
#: at another pace than before)
GAP_DISTANCES_M = (0.3, 0.6, 0.9)


def retry_starts(odometry: MapOdometry, coarse: tuple, surface: MapSurface,
                 prediction: np.ndarray, searched: bool,
                 stamp_ns: int | None) -> Iterator[np.ndarray]:
    """Where to align a frame from when the prediction failed, in order (see the module
    docstring); ``searched``: the prediction was a searched start already."""
    if odometry.pose_ is not None and not np.array_equal(prediction, odometry.pose_):
        yield odometry.pose_
    if not searched and odometry.params.search_steps:
        start = searched_start(odometry, coarse, surface, prediction)
        if start is not prediction:
            yield start
    candidates = relocalisation_starts(odometry, stamp_ns) if odometry.params.relocalise else []
    if candidates:
        best, agreement = best_start(odometry, coarse, surface, candidates)
        if agreement > 0.0:
            yield best
            if odometry.params.search_steps:
                around = searched_start(odometry, coarse, surface, best)
                if around is not best:
                    yield around


def searched_start(odometry: MapOdometry, coarse: tuple, surface: MapSurface,
                   prediction: np.ndarray) -> np.ndarray:
    """``prediction`` (4, 4), or the pose it moved by 1..``search_steps`` coarse gates along a
    camera axis (or turned about its x or y axis) whose coarse alignment agrees with
    `SEARCH_MARGIN` more of the frame."""
    p = odometry.params
    starts = [prediction]
    for axis, sign, k in itertools.product(range(3), (-1.0, 1.0),
                                           range(1, p.search_steps + 1)):
        shift = np.eye(4)
        shift[axis, 3] = sign * k * p.gates_m[0]
        starts.append(prediction @ shift)
        if axis < 2 and p.search_turn_deg:  # turned about the camera's x and y axes
            turn = np.eye(4)
            turn[:3, :3] = OK.so3_exp(np.radians(sign * k * p.search_turn_deg)
                                      * np.eye(3)[1 - axis])
            starts.append(prediction @ turn)
    agreements = coarse_agreements(odometry, coarse, surface, starts)
    best = int(np.argmax(agreements))
    return starts[best] if agreements[best] > agreements[0] + SEARCH_MARGIN else prediction


def relocalisation_starts(odometry: MapOdometry, stamp_ns: int | None) -> list[np.ndarray]:
    """Candidates over the whole map: the last motion continued over `GAP_SHARES` of the time
    since the last tracked frame (when frames carry stamps) and to `GAP_DISTANCES_M`, and the
    keyframes' poses, the most recent first."""
    starts = []
    pose, motion = odometry.pose_, odometry.velocity_
    if pose is not None and odometry.params.motion_model:
        fractions = []
        if odometry.motion_span_s_ > 0:
            motions = odometry.seconds_since(stamp_ns) / odometry.motion_span_s_
            fractions += [share * motions for share in GAP_SHARES if motions > 0]
        step = float(np.linalg.norm(motion[:3, 3]))
        if step > 1e-4:
            fractions += [distance / step for distance in GAP_DISTANCES_M]
        starts += [pose @ OK.scaled_motion(motion, fraction) for fraction in fractions]
    starts += list(reversed(odometry.keyframes))
    return starts


def best_start(odometry: MapOdometry, coarse: tuple, surface: MapSurface,
               starts: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """The start whose coarse alignment agrees with the most of the frame, and how much."""
    agreements = coarse_agreements(odometry, coarse, surface, starts)
    best = int(np.argmax(agreements))
    return starts[best], agreements[best]


def coarse_agreements(odometry: MapOdometry, coarse: tuple, surface: MapSurface,
                      starts: list[np.ndarray]) -> list[float]:
    """Each start's coarse alignment: overlap times inlier share (-1: too few points, or an
    implausible jump from it)."""
    agreements = []
    for start in starts:
        _, reason, stats = odometry.align([coarse], surface, start, SEARCH_ITERATIONS)
        agreements.append(-1.0 if reason in ("too few points", "implausible motion")
                          else stats["overlap"] * stats["inlier_share"])
    return agreements
