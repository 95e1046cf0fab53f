"""What capture did with a source's frames, for its end of stream (``gngdt.StreamEnd``) and its
exit status: the frames it refused, by why; those it sent without a cloud; what it warns about
the stream as a whole (camera parameters assumed, depth an RGB-D camera cannot have measured).

A refused frame is said in the log the first time its reason comes, and counted; the end of
stream carries the counts, so that `gngdt run` (or anyone on the camera's topics) says why a
file gave the learner nothing (docs/contracts.md, `gngdt/<cam>/eos`).
"""

from __future__ import annotations

import logging
from collections import Counter
from typing import TYPE_CHECKING, Protocol

from gngdt.core.sensor.depth import DepthRange
from gngdt.io.import_checks import DEPTH_CHECK_FRAMES, depth_warning

if TYPE_CHECKING:
    import threading

    from gngdt.io.deproject import CloudOptions
    from gngdt.io.frame import Frame

log = logging.getLogger(__name__)

#: distinct refusal reasons kept (a damaged file could give a new one per frame)
MAX_REASONS = 20
#: longest reason kept, characters
MAX_REASON_CHARS = 300
#: the reason the surplus reasons are counted under
OTHER_REASONS = "other reasons"


class CaptureTally:
    """Frames refused by reason, frames sent without a cloud, and the stream's warnings (the
    source's assumptions, then the depth check over its first `DEPTH_CHECK_FRAMES` frames with
    depth)."""

    def __init__(self) -> None:
        self.refused: Counter[str] = Counter()
        #: frames sent with their images only, by why
        self.without_cloud: Counter[str] = Counter()
        self.warnings: list[str] = []
        self._depth = DepthRange()
        self._depth_judged = False

    def refuse(self, where: str, reason: str) -> None:
        """A frame not sent: said the first time its ``reason`` comes (``where``: the file and
        frame), counted always."""
        reason = _count(self.refused, reason)
        if self.refused[reason] == 1:
            log.error("%s: %s; skipped (frames refused for this reason are counted, not said "
                      "again)", where, reason)

    def no_cloud(self, where: str, reason: str) -> None:
        """A frame sent with its images but no cloud: said the first time its ``reason``
        comes, counted always."""
        reason = _count(self.without_cloud, reason)
        if self.without_cloud[reason] == 1:
            log.warning("%s: %s; its images are sent, not its cloud (such frames are counted, "
                        "not said again)", where, reason)

    def bad_frame(self, error: Exception) -> None:
        """A frame the source could not read (`gngdt.io.errors.RecordingError`: its file,
        frame and reason; reading goes on)."""
        reason = getattr(error, "reason", None) or str(error)
        where = str(error)[:-len(reason)].rstrip(": ") if str(error).endswith(reason) else ""
        self.refuse(where or "a frame", reason)

    def reading_stopped(self, error: Exception) -> None:
        """The source could not be read on (damage to the file, a calibration refused): a
        warning of the stream, so that its end of stream says why it ended early."""
        warning = f"the reading stopped: {str(error)[:MAX_REASON_CHARS]}"
        if warning not in self.warnings:  # a file looped over says it once
            self.warnings.append(warning)

    def check_depth(self, frame: Frame) -> None:
        """Add the frame's depth to the check until it is judged, then warn once when the
        depth is implausible (`depth_warning`)."""
        if self._depth_judged:
            return
        self._depth.add(frame.depth)
        if self._depth.frames_with_depth >= DEPTH_CHECK_FRAMES:
            self.judge_depth()

    def judge_depth(self) -> None:
        """Judge the depth seen so far (at the end of a short stream), once."""
        if self._depth_judged or not self._depth.frames:
            return
        self._depth_judged = True
        warning = depth_warning(self._depth)
        if warning:
            log.warning("%s", warning)
            self.warnings.append(warning)

    def describe(self) -> str:
        """``"60 frames refused: --camera-json is for 320x240, colour is 640x480 (60)"``, and
        the frames sent without a cloud, by why ("" when neither)."""
        parts = []
        for counts, what in ((self.refused, "frames refused"),
                             (self.without_cloud, "frames sent without their cloud")):
            if counts:
                reasons = "; ".join(f"{reason} ({count})" for reason, count in
                                    counts.most_common())
                parts.append(f"{sum(counts.values())} {what}: {reasons}")
        return "; ".join(parts)


def no_points_reason(options: CloudOptions) -> str:
    """Why a frame's cloud is empty: no pixel in the depth range."""
    return (f"no depth between --min-depth {options.min_depth_m:g} m and --max-depth "
            f"{options.max_depth_m:g} m")


def _count(counts: Counter[str], reason: str) -> str:
    """Count one more frame under ``reason`` (cut to `MAX_REASON_CHARS`; beyond `MAX_REASONS`
    reasons, under `OTHER_REASONS`); the reason it was counted under."""
    reason = reason[:MAX_REASON_CHARS]
    if reason not in counts and len(counts) >= MAX_REASONS:
        reason = OTHER_REASONS
    counts[reason] += 1
    return reason


class ReplayOutcome(Protocol):
    """How a replay went (`gngdt.services.capture.Replay`)."""

    frames_read: int
    frames_sent: int
    error: Exception | None
    learner_lost: str
    stop: threading.Event
    tally: CaptureTally


def exit_status(replay: ReplayOutcome, live: bool) -> int:
    """2: the source gave no frame to send (unreadable, or every frame refused: said); 1: the
    learner stopped taking frames, or the camera was lost mid-stream; else 0 (a stop signal
    included)."""
    if replay.frames_read == 0 and replay.error is not None:
        log.error("%s", replay.error)
        return 2
    if replay.frames_sent == 0 and not replay.stop.is_set():
        refused = replay.tally.describe() or "the source had none"
        log.error("sent no frame: %s", refused)
        return 2
    if replay.learner_lost:
        return 1
    return 1 if live and replay.error is not None else 0  # a camera lost mid-stream
