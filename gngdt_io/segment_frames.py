"""Segments of every frame of a source: each frame deprojected to an organized point array and
segmented by GNG-DT (`gngdt.core.learner.frame_segmenter.FrameSegmenter`), online or independent;
what `gngdt segment` writes and `gngdt eval segmentation` scores."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from gngdt.core.learner.frame_segmenter import FrameResult, FrameSegmenter
from gngdt.io.deproject import Deprojector
from gngdt.io.frame import Frame
from gngdt.io.profiles import Profile
from gngdt.io.sources import FrameSource


@dataclass
class SegmentedFrame:
    """One frame, its organized points and what the segmenter made of it."""

    name: str
    frame: Frame
    #: (H, W, 3) float32 metres, NaN where there is no depth
    points: np.ndarray
    result: FrameResult
    #: milliseconds per phase: deproject + the segmenter's phases, and their ``total``
    milliseconds: dict[str, float]


def organized_frames(source: FrameSource) -> Iterator[tuple[str, Frame, np.ndarray, float]]:
    """(name, frame, points, milliseconds) of every frame of ``source``: points (H, W, 3)
    float32 metres in the camera frame, NaN where the depth is 0; milliseconds of deprojection.
    Raises RecordingError naming the file for a frame that cannot be read."""
    deproject = Deprojector(min_depth_m=0.0, max_depth_m=math.inf)  # only "no depth" is dropped
    for name, frame in source.frames():
        started = time.perf_counter()
        points = deproject.organized(frame.depth, frame.intrinsics)
        yield name, frame, points, (time.perf_counter() - started) * 1000.0


def segment_frames(source: FrameSource, segmenter: FrameSegmenter, independent: bool
                   ) -> Iterator[SegmentedFrame]:
    """Deproject and segment every frame of ``source`` in order (online unless
    ``independent``). Raises RecordingError naming the file for a frame that cannot be read."""
    for name, frame, points, deproject_ms in organized_frames(source):
        result = segmenter.segment_frame(points, frame.color, independent=independent)
        milliseconds = {"deproject": deproject_ms, **result.milliseconds}
        milliseconds["total"] = sum(milliseconds.values())
        yield SegmentedFrame(name, frame, points, result, milliseconds)


def timing_summary(per_frame: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Per phase: mean, p50, p90 and max of the frames' milliseconds (phases in first-seen
    order; a frame without a phase counts as 0 ms for it)."""
    phases = list(dict.fromkeys(name for frame in per_frame for name in frame))
    summary = {}
    for phase in phases:
        values = np.array([frame.get(phase, 0.0) for frame in per_frame], dtype=np.float64)
        summary[phase] = {"mean": float(values.mean()), "p50": float(np.percentile(values, 50)),
                          "p90": float(np.percentile(values, 90)), "max": float(values.max())}
    return summary


def make_segmenter(profile: Profile, seed: int = 0) -> FrameSegmenter:
    """The frame segmenter a sensor profile describes (`gngdt.io.profiles`)."""
    config = profile.config
    return FrameSegmenter(config.model, config.segmentation, profile.segmenter_schedule(), seed)
