"""What `gngdt run` says at the end: how the stream went, what was learned, the files written,
and warnings a user should act on."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo


def file_size(path: Path | None) -> str:
    """``"12.3 MB"``, or a note that the file is missing."""
    if path is None or not path.is_file():
        return "not written"
    return f"{path.stat().st_size / 1e6:.1f} MB"


def format_summary(status: LearnerStatusInfo | None, end: StreamEndInfo | None,
                   destination: str, recorded_frames: int | None = None,
                   early_end: str = "", outputs: list[str] | None = None,
                   node_budget: int | None = None, mode: str = "") -> str:
    """The lines ``run`` prints at the end; ``early_end`` says why the stream ended before the
    recording did; ``node_budget``: the learner's, to say when the network stayed small;
    ``mode``: how the source went to the learner."""
    sent = str(end.frames_sent) if end else "no end of stream"
    if end and recorded_frames is not None:
        sent += f" of {recorded_frames} in the recording"
    lines = [*([f"mode:               {mode}"] if mode else []), f"frames sent:        {sent}"]
    if early_end:
        lines.append(f"ended early:        {early_end}")
    if status is None:
        lines.append("learner:            no status received")
    else:
        clusters = ", ".join(f"{name} {count}" for name, count in
                             sorted(status.cluster_counts.items()))
        lines += [
            f"frames learned:     {learned_share(status, end)} ({status.frames_dropped} dropped, "
            f"{status.malformed_messages} malformed)",
            f"learning steps:     {status.steps} ({status.steps_per_second:,.0f} steps/s)",
            f"nodes:              {status.nodes}",
            f"forgetting:         {status.nodes_forgotten} nodes forgotten; ghost share "
            f"{status.ghost_share:.1%} (seen nodes > {status.ghost_distance_m * 100:g} cm from "
            "the last frame)",
            *([f"last frame:         {status.settle_reason}"] if status.settled else []),
            *pose_lines(status),
            *tracking_lines(status, end),
            f"clusters:           {clusters}",
            f"latency:            p50 {status.latency_p50_ms:.1f} ms, "
            f"p99 {status.latency_p99_ms:.1f} ms",
        ]
    lines.append(f"rerun:              {destination}")
    lines += outputs or []
    lines += [f"WARNING: {warning}" for warning in summary_warnings(status, end, node_budget)]
    return "\n".join(lines)


#: below this share of the frames sent, the summary warns that the learner did not keep up
MIN_LEARNED_SHARE = 0.5


def learned_share(status: LearnerStatusInfo, end: StreamEndInfo | None) -> str:
    """``"37 of 50 sent (74 %)"``, or the count alone without an end of stream."""
    if end is None or end.frames_sent == 0:
        return str(status.frames_used)
    return (f"{status.frames_used} of {end.frames_sent} sent "
            f"({status.frames_used / end.frames_sent:.0%})")


def summary_warnings(status: LearnerStatusInfo | None, end: StreamEndInfo | None,
                     node_budget: int | None = None) -> list[str]:
    """What the user should know about how the run learned: a learner that did not keep up,
    a network that stayed small because the recording was short."""
    if status is None or end is None or end.frames_sent == 0:
        return []
    warnings = []
    share = status.frames_used / end.frames_sent
    if share < MIN_LEARNED_SHARE:
        warnings.append(
            f"the learner kept up with only {share:.0%} of the frames (latest frame wins: it "
            "skips what arrives while it learns), so the network saw few views; the machine is "
            "busy or the frames are large: replay slower (--rate 0.5), cap the clouds "
            "(--max-points) or learn fewer steps per frame (--samples-per-frame)")
    if node_budget and status.nodes < node_budget / 2:
        warnings.append(
            f"the network has {status.nodes} of its {node_budget} nodes: it grows one node per "
            f"lambda steps, and it learned {status.steps:,} steps in all ({status.frames_used} "
            "frames and the settling on the last one); a longer recording or more steps per "
            "frame (--samples-per-frame) grow it")
    return warnings


def recorded_frames(spec: str) -> int | None:
    """Frames in an MCAP recording by its index (None without one, or for another source)."""
    from gngdt.io.mcap.reader import RecordingError, recording_info

    try:
        return int(recording_info(Path(spec))["frames"])
    except (RecordingError, OSError):
        return None


def pose_lines(status: LearnerStatusInfo) -> list[str]:
    """The summary's line on rejected poses (none when every pose passed)."""
    if not status.frames_pose_rejected:
        return []
    return [f"poses rejected:     {status.frames_pose_rejected} frames not learned; the last: "
            f"{status.pose_problem}"]


def tracking_lines(status: LearnerStatusInfo, end: StreamEndInfo | None) -> list[str]:
    """The summary's line on camera tracking (none when the learner did not track): frames
    posed of those sent, those lost and why, those the tracker did not reach in time."""
    lost = status.frames_lost_tracking
    if not status.frames_posed and not lost:
        return []
    sent = end.frames_sent if end is not None and end.frames_sent else None
    posed = f"{status.frames_posed} of {sent} frames posed ({status.frames_posed / sent:.0%})" \
        if sent else f"{status.frames_posed} frames posed"
    reasons = ", ".join(f"{reason} {count}" for reason, count in
                        sorted(status.frames_lost_by_reason.items(), key=lambda item: -item[1]))
    lines = [f"tracking:           {posed}; {lost} lost" + (f" ({reasons})" if reasons else "")]
    if status.frames_dropped:
        lines.append(f"                    {status.frames_dropped} not reached in time "
                     "(dropped before tracking: the machine is busy or the frames are large)")
    return lines


def mostly_rejected(status: LearnerStatusInfo | None) -> bool:
    """Whether more frames were rejected for their pose than learned: the run failed."""
    return status is not None and status.frames_pose_rejected > status.frames_used
