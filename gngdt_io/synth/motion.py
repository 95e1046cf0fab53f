"""What moves in a synthetic recording: the camera along a path (:class:`Orbit`, :class:`Walk`,
built on :func:`look_at`) and primitives that slide or vanish (:class:`Motion`).

World frame: x right, y forward, z up, metres; camera axes x right, y down, z forward.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CameraPath", "Motion", "Orbit", "Walk", "look_at"]


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``(4, 4) float64`` world_from_camera of a camera at ``position`` looking at ``target``,
    level (its x axis horizontal); camera axes x right, y down, z forward."""
    forward = target - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([right, down, forward])
    pose[:3, 3] = position
    return pose


@dataclass(frozen=True)
class Orbit:
    """A slow camera arc around ``target``, always looking at it.

    At time ``s`` seconds the camera sits ``distance + distance_swing * sin(w s)`` metres from the
    target at azimuth ``azimuth_deg + azimuth_swing_deg * sin(w s)`` (0 = on the -y side) and
    elevation ``elevation_deg + elevation_swing_deg * sin(w s / 2)``, with ``w = 2 pi / period_s``.
    """

    target: tuple[float, float, float]
    distance: float
    elevation_deg: float
    azimuth_swing_deg: float
    period_s: float
    azimuth_deg: float = 0.0
    elevation_swing_deg: float = 0.0
    distance_swing: float = 0.0

    def pose(self, time_s: float) -> np.ndarray:
        """``(4, 4) float64`` world_from_camera (camera axes: x right, y down, z forward)."""
        phase = 2.0 * math.pi * time_s / self.period_s
        azimuth = math.radians(self.azimuth_deg + self.azimuth_swing_deg * math.sin(phase))
        elevation = math.radians(
            self.elevation_deg + self.elevation_swing_deg * math.sin(phase / 2.0)
        )
        distance = self.distance + self.distance_swing * math.sin(phase)
        target = np.asarray(self.target, dtype=np.float64)
        position = target + distance * np.array(
            [
                math.cos(elevation) * math.sin(azimuth),
                -math.cos(elevation) * math.cos(azimuth),
                math.sin(elevation),
            ]
        )
        return look_at(position, target)


@dataclass(frozen=True)
class Walk:
    """A camera that travels from ``start`` to ``end`` and back (positions, metres), looking at a
    point that travels from ``look_start`` to ``look_end`` with it.

    One way takes ``period_s / 2`` seconds; the speed follows a cosine, so the camera eases out
    of and into both ends: at time ``s`` it is the fraction ``(1 - cos(2 pi s / period_s)) / 2``
    of the way.
    """

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    look_start: tuple[float, float, float]
    look_end: tuple[float, float, float]
    period_s: float

    def pose(self, time_s: float) -> np.ndarray:
        """``(4, 4) float64`` world_from_camera (camera axes: x right, y down, z forward)."""
        fraction = 0.5 - 0.5 * math.cos(2.0 * math.pi * time_s / self.period_s)

        def along(first: tuple[float, ...], last: tuple[float, ...]) -> np.ndarray:
            a, b = np.asarray(first, dtype=np.float64), np.asarray(last, dtype=np.float64)
            return a + fraction * (b - a)

        return look_at(along(self.start, self.end), along(self.look_start, self.look_end))


#: how the camera moves: anything with ``pose(time_s) -> (4, 4)`` and ``period_s``
CameraPath = Orbit | Walk


@dataclass(frozen=True)
class Motion:
    """A change of one primitive during a recording (the scene is static without any).

    From ``start_s`` to ``end_s`` (seconds from the first frame) the primitive ``primitive``
    slides by ``offset (3,)`` metres at constant speed and then stays; with ``vanish`` it is gone
    from ``start_s`` on (``offset`` and ``end_s`` unused). Segment ids never change: a vanished
    primitive's ids are simply no longer seen.
    """

    primitive: str
    start_s: float
    end_s: float | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    vanish: bool = False

    def displacement(self, time_s: float) -> np.ndarray:
        """``(3,)`` metres the primitive has moved by ``time_s``."""
        if time_s <= self.start_s:
            return np.zeros(3)
        span = (self.end_s if self.end_s is not None else self.start_s) - self.start_s
        fraction = 1.0 if span <= 0 else min(1.0, (time_s - self.start_s) / span)
        return fraction * np.asarray(self.offset, dtype=np.float64)

    def describe(self, fps: float) -> dict[str, object]:
        """The motion as recording metadata: frames rather than seconds."""
        end_s = self.end_s if self.end_s is not None else self.start_s
        return {
            "primitive": self.primitive,
            "kind": "vanish" if self.vanish else "move",
            "start_frame": math.ceil(self.start_s * fps - 1e-9),
            "end_frame": math.ceil(end_s * fps - 1e-9),
            "offset_m": list(self.offset),
        }
