"""How a run ended, as its exit status: which of its services said no, and what the person at
the terminal is told to do about it (docs/contracts.md "Command line", ``gngdt run --help``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from gngdt.services.run.observe import LearnerAcks

if TYPE_CHECKING:
    from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo
    from gngdt.services.run.children import Child

#: the run did what it was asked
DONE = 0
#: a service failed, or the stream ended before the recording did (the reason printed)
FAILED = 1
#: the input is unusable: refused before anything started (an option, a file that is not a
#: recording, nothing listening at --ros2), or capture refused every frame (its reasons printed)
INPUT_UNUSABLE = 2
#: the learner learned nothing, or rejected most frames' poses (its reasons printed)
NOTHING_LEARNED = 3
#: an output stopped before the end: the .rrd or MCAP writer (a full disk, --min-free-mb,
#: --max-rrd-mb, --max-mcap-mb), named with its reason in the summary
OUTPUT_STOPPED = 4
#: a stop signal (Ctrl-C) ended the run
INTERRUPTED = 130

EXIT_STATUS_HELP = f"""exit status:
  {DONE}    done
  {FAILED}    a service failed, or the stream ended before the recording did (the reason printed)
  {INPUT_UNUSABLE}    the input is unusable: a wrong option or source, nothing listening at --ros2,
       or capture refused every frame (its reasons printed)
  {NOTHING_LEARNED}    the learner learned nothing, or rejected most frames' poses (its reasons)
  {OUTPUT_STOPPED}    the .rrd or MCAP writer stopped early (disk full, --min-free-mb, --max-rrd-mb,
       --max-mcap-mb): the summary says which and why
  {INTERRUPTED}  interrupted (Ctrl-C)
"""


@dataclass
class RunOutcome:
    """How a run went: what the run's own router heard (``status``, ``end``, ``acks``), which
    service failed, and what its logger and bridge reported (`--report`)."""

    status: LearnerStatusInfo | None
    end: StreamEndInfo | None
    early_end: str
    failure: Child | None
    interrupted: bool
    acks: LearnerAcks = field(default_factory=LearnerAcks)
    logger_report: dict[str, Any] = field(default_factory=dict)
    ros2_report: dict[str, Any] = field(default_factory=dict)
    #: how long the servers served after the file ended (None: they did not)
    lingered: float | None = None

    @property
    def stopped_outputs(self) -> list[dict[str, Any]]:
        """The logger's outputs that stopped writing before the end (where, and why)."""
        return [output for output in self.logger_report.get("outputs", [])
                if isinstance(output, dict) and output.get("stopped_early")]

    @property
    def learned_nothing(self) -> bool:
        """The stream ended, frames were sent, and the learner learned none of them."""
        if self.end is None or self.failure is not None or self.interrupted:
            return False
        learned = self.acks.outcomes["learned"] if self.acks.total else (
            0 if self.status is None else self.status.frames_used)
        return self.end.frames_sent > 0 and learned == 0

    @property
    def mostly_rejected(self) -> bool:
        """More frames were rejected for their pose than learned."""
        status = self.status
        return status is not None and status.frames_pose_rejected > status.frames_used


def exit_status(outcome: RunOutcome) -> tuple[int, str]:
    """The run's exit status (`EXIT_STATUS_HELP`) and, when the summary alone does not say it,
    why (a sentence to log after the summary; "" otherwise)."""
    failure = outcome.failure
    if outcome.interrupted:
        return INTERRUPTED, ""
    if failure is not None:
        code = failure.process.returncode
        return (INPUT_UNUSABLE if failure.name == "capture" and code == INPUT_UNUSABLE
                else FAILED), ""
    if outcome.early_end:
        return FAILED, ""
    if outcome.learned_nothing:
        return NOTHING_LEARNED, (
            "the learner learned nothing (see 'refused by learner', 'sent without cloud' and "
            "the warnings above: depth in another unit than depth_scale says? `gngdt record "
            "images` prints the depth range it found)")
    if outcome.mostly_rejected:
        return NOTHING_LEARNED, (
            "most frames were not learned: their camera poses are out of bounds or contradict "
            "their depth (see 'poses rejected' above; `gngdt record images --poses` names the "
            "usual misreadings of a pose file)")
    if outcome.stopped_outputs:
        return OUTPUT_STOPPED, (" and ".join(output["where"] for output in outcome.stopped_outputs)
                                + " stopped writing before the end (see the WARNING above)")
    return DONE, ""
