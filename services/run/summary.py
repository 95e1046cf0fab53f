"""What `gngdt run` says at the end: how the stream went, what was learned, the files written,
and warnings a user should act on."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from gngdt.services.run.observe import LearnerAcks

if TYPE_CHECKING:
    from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo


def file_size(path: Path | None) -> str:
    """``"12.3 MB"``, or a note that the file is missing."""
    if path is None or not path.is_file():
        return "not written"
    return f"{path.stat().st_size / 1e6:.1f} MB"


@dataclass
class RunFacts:
    """What a run's summary says: what its router heard (``status``, ``end``, ``acks``), what
    it wrote and served (``destination`` and ``outputs``: lines), and what to warn about.

    ``early_end``: why the stream ended before the recording did; ``node_budget``: the
    learner's, to say when the network stayed small; ``mode``: how the source went to the
    learner (``paced``: a file read frame by frame, where a frame the learner never took was
    not dropped but left behind); ``warnings``: the run's own (an output that stopped early)."""

    status: LearnerStatusInfo | None
    end: StreamEndInfo | None
    acks: LearnerAcks = field(default_factory=LearnerAcks)
    destination: str = ""
    recorded_frames: int | None = None
    early_end: str = ""
    outputs: list[str] = field(default_factory=list)
    node_budget: int | None = None
    mode: str = ""
    paced: bool = False
    warnings: list[str] = field(default_factory=list)

    @property
    def learned(self) -> int:
        """Frames learned in this run (its acknowledgements; the status counts a resumed
        checkpoint's too)."""
        if self.acks.total or self.status is None:
            return self.acks.outcomes["learned"]
        return self.status.frames_used


def format_summary(facts: RunFacts) -> str:
    """The lines ``run`` prints at the end."""
    status, end = facts.status, facts.end
    sent = str(end.frames_sent) if end else "no end of stream"
    if end and facts.recorded_frames is not None:
        sent += f" of {facts.recorded_frames} in the recording"
    lines = [*([f"mode:               {facts.mode}"] if facts.mode else []),
             f"frames sent:        {sent}", *capture_lines(end)]
    if facts.early_end:
        lines.append(f"ended early:        {facts.early_end}")
    if end is not None and (facts.acks.total or status is not None):
        lines += frame_lines(facts)
    if status is None:
        lines.append("learner:            no status received")
    else:
        clusters = ", ".join(f"{name} {count}" for name, count in
                             sorted(status.cluster_counts.items()))
        lines += [
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
    lines.append(f"rerun:              {facts.destination}")
    lines += facts.outputs
    warnings = [*(end.warnings if end else []),
                *summary_warnings(status, end, facts.node_budget, facts.learned),
                *facts.warnings]
    lines += [f"WARNING: {warning}" for warning in warnings]
    return "\n".join(lines)


def capture_lines(end: StreamEndInfo | None) -> list[str]:
    """What capture did not send, or sent without a cloud, by why (from its end of stream)."""
    if end is None:
        return []
    lines = []
    for counts, label in ((end.frames_refused, "refused by capture:"),
                          (end.frames_without_cloud, "sent without cloud:")):
        if counts:
            reasons = "; ".join(f"{reason} ({count})" for reason, count in
                                sorted(counts.items(), key=lambda item: -item[1]))
            lines.append(f"{label:<20}{sum(counts.values())} frames: {reasons}")
    return lines


#: the learner's outcomes that refuse a frame (`gngdt.FrameAck`), as the summary names them
REFUSALS = ("pose rejected", "lost tracking", "other frame")


def frame_lines(facts: RunFacts) -> list[str]:
    """Frames learned of those sent, and every frame sent accounted for, each kind named:
    sent = learned + dropped + malformed + refused (+ posed, not learned; + sent without a
    cloud; + left behind), from the learner's acknowledgements and capture's end of stream."""
    end, outcomes = facts.end, facts.acks.outcomes
    sent, learned = end.frames_sent, facts.learned
    refused = sum(outcomes[outcome] for outcome in REFUSALS)
    without_cloud = sum(end.frames_without_cloud.values())
    acknowledged = facts.acks.total if facts.acks.total else learned
    unacknowledged = max(sent - acknowledged - without_cloud, 0)
    dropped, behind = (0, unacknowledged) if facts.paced else (unacknowledged, 0)
    terms = [f"{learned} learned", f"{dropped} dropped", f"{outcomes['malformed']} malformed",
             f"{refused} refused"]
    for count, name in ((outcomes["posed"], "posed, not learned (--track: another frame "
                         "of their view was)"),
                        (without_cloud, "sent without a cloud"),
                        (behind, "left behind (the learner stopped before it took them)")):
        if count:
            terms.append(f"{count} {name}")
    share = f" ({learned / sent:.0%})" if sent else ""
    lines = [f"frames learned:     {learned} of {sent} sent{share}",
             f"every frame sent:   {sent} = {' + '.join(terms)}"]
    problems = facts.acks.first_problem
    reasons = [f"{outcome} {outcomes[outcome]}"
               + (f" (the first: {problems[outcome]})" if outcome in problems else "")
               for outcome in (*REFUSALS, "malformed") if outcomes[outcome]]
    if reasons:
        lines.append(f"refused by learner: {'; '.join(reasons)}")
    return lines


#: below this share of the frames sent, the summary warns that the learner did not keep up
MIN_LEARNED_SHARE = 0.5


def summary_warnings(status: LearnerStatusInfo | None, end: StreamEndInfo | None,
                     node_budget: int | None, learned: int) -> list[str]:
    """What the user should know about how the run learned (``learned`` frames): a learner
    that did not keep up, a network that stayed small because the recording was short."""
    if status is None or end is None or end.frames_sent == 0:
        return []
    warnings = []
    share = learned / end.frames_sent
    # not kept up: most frames not learned were dropped (not refused: the summary says why)
    if share < MIN_LEARNED_SHARE and 2 * status.frames_dropped >= end.frames_sent - learned:
        warnings.append(
            f"the learner kept up with only {share:.0%} of the frames (latest frame wins: it "
            "skips what arrives while it learns), so the network saw few views; the machine is "
            "busy or the frames are large: replay slower (--rate 0.5), cap the clouds "
            "(--max-points) or learn fewer steps per frame (--samples-per-frame)")
    if node_budget and status.nodes < node_budget / 2:
        warnings.append(
            f"the network has {status.nodes} of its {node_budget} nodes: it grows one node per "
            f"lambda steps, and it learned {status.steps:,} steps in all ({learned} "
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
