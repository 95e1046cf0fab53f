"""What `gngdt run` hears on its own router: the services' liveliness, the learner's status and
acknowledgements, capture's end of stream."""

from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import zenoh

    from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo


@dataclass
class LearnerAcks:
    """The learner's acknowledgements (`gngdt.FrameAck`), one per cloud it was done with:
    how many had each outcome ("learned", "posed", "pose rejected", ...), and the first reason
    given for each outcome that is not "learned"."""

    outcomes: Counter[str] = field(default_factory=Counter)
    first_problem: dict[str, str] = field(default_factory=dict)

    def add(self, outcome: str, problem: str) -> None:
        self.outcomes[outcome] += 1
        if problem and outcome not in self.first_problem:
            self.first_problem[outcome] = problem

    @property
    def total(self) -> int:
        return sum(self.outcomes.values())


@dataclass
class Observed:
    """What ``run`` hears on its own router session: liveliness, status, acknowledgements and
    the end of stream."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    alive: set[str] = field(default_factory=set)
    status: LearnerStatusInfo | None = None
    end: StreamEndInfo | None = None
    acks: LearnerAcks = field(default_factory=LearnerAcks)

    def on_liveliness(self, sample: zenoh.Sample) -> None:
        import zenoh

        key = str(sample.key_expr)
        with self.lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(key)
            else:
                self.alive.discard(key)

    def on_status(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.messages import MessageError
        from gngdt.schemas.status import decode_status

        try:
            status = decode_status(sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.status = status

    def on_eos(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.messages import MessageError
        from gngdt.schemas.status import decode_stream_end

        try:
            end = decode_stream_end(sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.end = end

    def on_ack(self, sample: zenoh.Sample) -> None:
        from gngdt.schemas.messages import MessageError
        from gngdt.schemas.status import decode_frame_ack

        try:
            ack = decode_frame_ack(sample.payload.to_bytes())
        except MessageError:
            return
        with self.lock:
            self.acks.add(ack.outcome, ack.problem)

    def has_alive(self, prefix: str) -> bool:
        with self.lock:
            return any(key.startswith(prefix) for key in self.alive)
