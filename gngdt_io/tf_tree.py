"""Rigid transforms between named frames over time, looked up the way ROS tf2 does.

A transform ``parent -> child`` is the child frame's pose in the parent frame: it maps a point
given in the child frame into the parent frame, ``p_parent = R p_child + t`` (ROS
``TransformStamped`` and ``foxglove.FrameTransform`` both mean this). Every frame has at most one
parent, so the frames form trees; a lookup walks from both frames up to their common ancestor.
Static transforms (``/tf_static``) hold at every time; the others are interpolated at the
requested time (linear translation, spherical-linear rotation) between the two samples around
it, and held for at most ``max_extrapolation_ns`` beyond the first or last sample.

Quaternions are (x, y, z, w), checked as :mod:`gngdt.core.sensor.geometry` does (the rigid-transform
math lives there; ``TransformError``, ``QUATERNION_TOLERANCE``, ``pose_to_matrix``,
``matrix_to_pose`` and ``unit_quaternion`` are re-exported here).
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass, field

import numpy as np

from gngdt.core.sensor.geometry import (
    QUATERNION_TOLERANCE,
    TransformError,
    checked_translation,
    matrix_to_pose,
    pose_to_matrix,
    quaternion_to_rotation,
    rigid_inverse,
    slerp,
    unit_quaternion,
)

__all__ = [
    "QUATERNION_TOLERANCE",
    "TransformError",
    "TransformTree",
    "matrix_to_pose",
    "pose_to_matrix",
    "unit_quaternion",
]

#: a lookup may use the first/last sample this far outside the samples' time span (20 ms: a
#: camera frame stamped just after the last transform of a 50 Hz stream still gets it)
DEFAULT_MAX_EXTRAPOLATION_NS = 20_000_000
#: links (frames with a parent) a tree holds: each new link walks its parent's chain, so a
#: tree of a million frames would cost hours; a robot's has a few dozen
MAX_LINKS = 1024
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1


@dataclass
class _Link:
    """The samples of one parent -> child transform: 64 bytes each, twice that once looked up
    (a recording may hold millions), appended in any order and sorted by time when first looked
    up."""

    parent: str
    static: bool
    #: the tree's lookup count when a lookup last used this link (0: never)
    used: int = 0
    #: stamps (S,) in ns and (S, 7) translation + quaternion (x, y, z, w) rows, as added
    _stamps: array = field(default_factory=lambda: array("q"))
    _values: array = field(default_factory=lambda: array("d"))
    #: the same, sorted by stamp (stable), built at the first lookup after a change
    _sorted: tuple[np.ndarray, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self._stamps)

    def add(self, stamp_ns: int, translation: np.ndarray, quaternion: np.ndarray) -> None:
        if self.static:  # the latest static transform replaces the previous one
            del self._stamps[:], self._values[:]
        self._stamps.append(stamp_ns)
        self._values.extend(translation.tolist() + quaternion.tolist())
        self._sorted = None

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """(S,) int64 stamps and (S, 7) float64 poses, sorted by stamp."""
        if self._sorted is None:
            stamps = np.frombuffer(self._stamps, dtype=np.int64)
            order = np.argsort(stamps, kind="stable")
            values = np.frombuffer(self._values, dtype=np.float64).reshape(-1, 7)
            self._sorted = stamps[order], values[order]
        return self._sorted

    def forget_before(self, stamp_ns: int) -> int:
        """Drop the samples older than ``stamp_ns``, keeping the newest one; how many went."""
        if self.static or len(self) < 2:
            return 0
        stamps, _ = self.samples()
        keep = min(int(np.searchsorted(stamps, stamp_ns)), len(stamps) - 1)
        return self._keep(slice(keep, None)) if keep else 0

    def forget_outside(self, start_ns: int, end_ns: int) -> int:
        """Drop the samples stamped outside [start_ns, end_ns] (all of them, possibly); how
        many went."""
        if self.static or not len(self):
            return 0
        stamps, _ = self.samples()
        first = int(np.searchsorted(stamps, start_ns))
        end = int(np.searchsorted(stamps, end_ns, side="right"))
        return self._keep(slice(first, max(first, end)))

    def discard(self, stamps_ns: np.ndarray) -> int:
        """Drop the samples stamped at any of ``stamps_ns``; how many went."""
        stamps, _ = self.samples()
        return self._keep(~np.isin(stamps, stamps_ns))

    def newest_ns(self) -> int:
        return int(self.samples()[0][-1])

    def _keep(self, kept: slice | np.ndarray) -> int:
        """Keep the sorted samples ``kept`` (a slice or a mask); how many went."""
        stamps, values = self.samples()
        before = len(stamps)
        self._stamps = array("q", stamps[kept].tobytes())
        self._values = array("d", values[kept].tobytes())
        self._sorted = None
        return before - len(self._stamps)

    def at(self, stamp_ns: int, max_extrapolation_ns: int, child: str) -> np.ndarray:
        """(4, 4) parent_from_child at ``stamp_ns``."""
        stamps, values = self.samples()
        if self.static:
            return pose_to_matrix(values[0, :3], values[0, 3:])
        first, last = int(stamps[0]), int(stamps[-1])
        if stamp_ns <= first or stamp_ns >= last:
            nearest = 0 if stamp_ns <= first else -1
            if abs(stamp_ns - int(stamps[nearest])) > max_extrapolation_ns:
                raise TransformError(
                    f"no transform {self.parent!r} -> {child!r} at {stamp_ns / 1e9:.3f} s: "
                    f"its {len(stamps)} samples span {first / 1e9:.3f}-{last / 1e9:.3f} s"
                )
            return pose_to_matrix(values[nearest, :3], values[nearest, 3:])
        after = int(np.searchsorted(stamps, stamp_ns))
        (t0, t1), (v0, v1) = stamps[after - 1: after + 1].tolist(), values[after - 1: after + 1]
        fraction = (stamp_ns - t0) / (t1 - t0) if t1 > t0 else 1.0
        matrix = np.eye(4)
        matrix[:3, :3] = quaternion_to_rotation(slerp(v0[3:], v1[3:], fraction))
        # weighted, not v0 + f (v1 - v0): a sample exactly at the stamp is returned exactly,
        # whatever its neighbour (1e18 beside 1.5 cancelled to 0 before)
        matrix[:3, 3] = (1.0 - fraction) * v0[:3] + fraction * v1[:3]
        return matrix


class TransformTree:
    """Transforms between named frames over time; see the module docstring."""

    def __init__(self, max_extrapolation_ns: int = DEFAULT_MAX_EXTRAPOLATION_NS,
                 max_links: int = MAX_LINKS, evict: bool = False) -> None:
        self.max_extrapolation_ns = int(max_extrapolation_ns)
        self.max_links = int(max_links)
        #: a full tree makes room for a new link by dropping the one lookups used least
        #: recently (a live /tf: a flood of made-up frames cannot lock the camera's out);
        #: else the new link is refused (a recording: its first links are kept)
        self.evict = evict
        self._links: dict[str, _Link] = {}  # child -> link to its parent
        self.samples = 0  # samples held, over every link
        self._lookups = 0

    def __len__(self) -> int:
        return len(self._links)

    @property
    def frames(self) -> set[str]:
        """Every frame named by a transform."""
        return set(self._links) | {link.parent for link in self._links.values()}

    def add(self, parent: str, child: str, stamp_ns: int, translation: object,
            quaternion: object, static: bool = False) -> None:
        """Add one sample of ``parent -> child``; ``TransformError`` naming the frames for an
        invalid one (empty or equal names, non-finite numbers, a non-unit quaternion, a child
        that already has another parent, a static/dynamic mix on one link, a stamp beyond
        int64 ns, more than ``max_links`` links)."""
        what = f"transform {parent!r} -> {child!r}"
        if not parent or not child or parent == child:
            raise TransformError(f"{what}: frame ids must be two different non-empty names")
        if not INT64_MIN <= stamp_ns <= INT64_MAX:
            raise TransformError(f"{what}: stamp {stamp_ns} ns is beyond 64 bits")
        t = checked_translation(translation, what)
        q = unit_quaternion(quaternion, what)
        link = self._links.get(child)
        if link is None:
            if len(self._links) >= self.max_links and self.evict:
                self._evict_least_used()
            if len(self._links) >= self.max_links:
                raise TransformError(f"{what}: more than {self.max_links} frames (a robot has "
                                     "a few dozen)")
            if child in self._ancestors(parent):
                raise TransformError(f"{what}: would close a loop")
            link = self._links[child] = _Link(parent, static)
        elif link.parent != parent:
            raise TransformError(f"{what}: {child!r} already has the parent {link.parent!r}")
        elif link.static != static:
            raise TransformError(f"{what}: published both as static and as dynamic")
        q = -q if q[3] < 0 else q  # one sign for each rotation, as matrix_to_pose gives
        self.samples += 0 if link.static and len(link) else 1  # a static one replaces
        link.add(int(stamp_ns), t, q)

    def forget_before(self, stamp_ns: int) -> None:
        """Drop the samples of dynamic transforms older than ``stamp_ns`` (each link keeps its
        newest one): a live ``/tf`` stream is held over a window, not for ever."""
        for link in self._links.values():
            self.samples -= link.forget_before(stamp_ns)

    def forget_stale(self, window_ns: int) -> None:
        """Drop each dynamic link's samples older than its own newest one minus ``window_ns``:
        links are held over a window each, so that one link stamped far ahead (a forgery,
        another clock) costs no other link its samples."""
        for link in self._links.values():
            if not link.static and len(link):
                self.samples -= link.forget_before(link.newest_ns() - window_ns)

    def forget_outside(self, start_ns: int, end_ns: int) -> int:
        """Drop the dynamic samples stamped outside [start_ns, end_ns] (the window around the
        time poses are looked up at); a link left with none goes, so its child may take
        another parent. How many samples went."""
        dropped = 0
        for child, link in list(self._links.items()):
            gone = link.forget_outside(start_ns, end_ns)
            dropped += gone
            if not link.static and not len(link):
                del self._links[child]
        self.samples -= dropped
        return dropped

    def discard(self, child: str, stamps_ns: np.ndarray) -> int:
        """Drop the samples of ``child``'s link stamped at any of ``stamps_ns`` (a link left
        with none goes); how many went."""
        link = self._links.get(child)
        if link is None:
            return 0
        gone = link.discard(stamps_ns)
        self.samples -= gone
        if not len(link):
            del self._links[child]
        return gone

    def _evict_least_used(self) -> None:
        """Drop the link lookups used least recently (the oldest of those never used)."""
        child = min(self._links, key=lambda name: self._links[name].used)
        self.samples -= len(self._links.pop(child))

    def _ancestors(self, frame: str) -> list[str]:
        """``frame`` and its parents up to its tree's root, in that order."""
        chain = [frame]
        while chain[-1] in self._links:
            chain.append(self._links[chain[-1]].parent)
        return chain

    def root(self, frame: str) -> str:
        """The root of the tree holding ``frame``."""
        return self._ancestors(frame)[-1]

    def chain(self, target: str, source: str) -> list[str] | None:
        """Frames from ``target`` to ``source`` through their common ancestor, or None when they
        are in different trees (or unknown)."""
        up_from_source = self._ancestors(source)
        up_from_target = self._ancestors(target)
        common = next((frame for frame in up_from_source if frame in up_from_target), None)
        if common is None:
            return None
        down = up_from_source[: up_from_source.index(common) + 1][::-1]
        return up_from_target[: up_from_target.index(common)] + down

    def lookup(self, target: str, source: str, stamp_ns: int) -> np.ndarray:
        """(4, 4) float64 ``target_from_source`` at ``stamp_ns``: maps points given in
        ``source`` into ``target``. ``TransformError`` naming the frames when the frames are not
        connected or a link has no sample near ``stamp_ns``."""
        up_from_source = self._ancestors(source)
        up_from_target = self._ancestors(target)
        common = next((frame for frame in up_from_source if frame in up_from_target), None)
        if common is None:
            raise TransformError(
                f"no transform chain from {target!r} to {source!r} "
                f"(known frames: {', '.join(sorted(self.frames)) or 'none'})"
            )

        self._lookups += 1

        def common_from(chain: list[str]) -> np.ndarray:
            matrix = np.eye(4)
            for child in chain[: chain.index(common)]:
                link = self._links[child]
                link.used = self._lookups
                matrix = link.at(stamp_ns, self.max_extrapolation_ns, child) @ matrix
            return matrix

        return rigid_inverse(common_from(up_from_target)) @ common_from(up_from_source)
