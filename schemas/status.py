"""Learner status, end-of-stream notices and frame acknowledgements: dataclasses <->
``gngdt.LearnerStatus``, ``gngdt.StreamEnd`` and ``gngdt.FrameAck``, field by field
(``timestamp_ns`` for the message's stamp)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

from google.protobuf.message import Message

import gngdt.schemas.gngdt_pb2 as gngdt_pb2
from gngdt.schemas.messages import MessageT, ns_to_timestamp, parse_message, timestamp_to_ns

__all__ = [
    "FrameAckInfo",
    "LearnerStatusInfo",
    "StreamEndInfo",
    "decode_frame_ack",
    "decode_status",
    "decode_stream_end",
    "encode_frame_ack",
    "encode_status",
    "encode_stream_end",
]


@dataclass
class LearnerStatusInfo:
    """One ``gngdt.LearnerStatus``: the message's field names, ``timestamp_ns`` for its stamp."""

    timestamp_ns: int = 0
    frame_sequence: int = 0
    frame_id: str = ""
    steps: int = 0
    steps_per_second: float = 0.0
    nodes: int = 0
    frames_received: int = 0
    frames_used: int = 0
    frames_dropped: int = 0
    malformed_messages: int = 0
    latency_ms: float = 0.0
    latency_p50_ms: float = 0.0
    latency_p99_ms: float = 0.0
    quantization_error: dict[str, float] = field(default_factory=dict)
    cluster_counts: dict[str, int] = field(default_factory=dict)
    #: after the stream ended: how learning on its last frame stopped ("" while streaming)
    settle_reason: str = ""
    seen_nodes: int = 0
    ghost_share: float = 0.0
    ghost_distance_m: float = 0.0
    nodes_forgotten: int = 0
    frames_other_frame: int = 0
    frames_pose_rejected: int = 0
    #: why the last rejected pose was rejected ("" while none was)
    pose_problem: str = ""
    frame_budget_ms: float = 0.0
    frame_steps: int = 0
    frames_lost_tracking: int = 0
    tracking: str = ""
    #: the stream ended and the learner settled on its last frame: nothing more will come
    settled: bool = False
    #: camera tracking: clouds whose camera was tracked (learned or not), those lost by why
    frames_posed: int = 0
    frames_lost_by_reason: dict[str, int] = field(default_factory=dict)


@dataclass
class StreamEndInfo:
    """One ``gngdt.StreamEnd``: a capture finished sending a recording."""

    timestamp_ns: int = 0
    frames_sent: int = 0
    last_frame_sequence: int = 0
    recording: str = ""
    frame_id: str = ""
    #: frames capture did not send, by why (the reason without the frame's index)
    frames_refused: dict[str, int] = field(default_factory=dict)
    #: frames sent with their images but no cloud, by why (no camera pose at their time, ...)
    frames_without_cloud: dict[str, int] = field(default_factory=dict)
    #: what capture warns about the stream as a whole (each naming what changes it)
    warnings: list[str] = field(default_factory=list)


@dataclass
class FrameAckInfo:
    """One ``gngdt.FrameAck``: the learner is done with one cloud (``outcome``: "learned", or
    why not, with ``problem``)."""

    timestamp_ns: int = 0
    frame_sequence: int = 0
    outcome: str = ""
    problem: str = ""


#: the messages' map fields (set and read as dicts)
MAP_FIELDS = ("quantization_error", "cluster_counts", "frames_lost_by_reason", "frames_refused",
              "frames_without_cloud")
#: the messages' repeated fields (read as lists)
REPEATED_FIELDS = ("warnings",)

_InfoT = TypeVar("_InfoT", LearnerStatusInfo, StreamEndInfo, FrameAckInfo)


def _info_to_message(
    info_type: type, message_type: type[MessageT], values: dict[str, Any]
) -> MessageT:
    known = {item.name for item in fields(info_type)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(
            f"{message_type.DESCRIPTOR.full_name} has no field(s) {', '.join(unknown)}"
        )
    values = dict(values)
    timestamp_ns = values.pop("timestamp_ns", 0)
    maps = {
        name: values.pop(name)
        for name in MAP_FIELDS
        if name in values
    }
    try:
        message = message_type(**values)
        for name, mapping in maps.items():
            getattr(message, name).update(mapping)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{message_type.DESCRIPTOR.full_name}: {error}") from error
    ns_to_timestamp(timestamp_ns, message.timestamp)
    return message


def _message_to_info(info_type: type[_InfoT], message: Message) -> _InfoT:
    values: dict[str, Any] = {}
    for item in fields(info_type):
        if item.name == "timestamp_ns":
            values[item.name] = timestamp_to_ns(message.timestamp)
        elif item.name in MAP_FIELDS:
            values[item.name] = dict(getattr(message, item.name))
        elif item.name in REPEATED_FIELDS:
            values[item.name] = list(getattr(message, item.name))
        else:
            values[item.name] = getattr(message, item.name)
    return info_type(**values)


def encode_status(**fields_: Any) -> gngdt_pb2.LearnerStatus:
    """``gngdt.LearnerStatus`` from keyword fields named as in :class:`LearnerStatusInfo`."""
    return _info_to_message(LearnerStatusInfo, gngdt_pb2.LearnerStatus, fields_)


def decode_status(message: gngdt_pb2.LearnerStatus | bytes) -> LearnerStatusInfo:
    """Decode a ``gngdt.LearnerStatus``."""
    return _message_to_info(LearnerStatusInfo, parse_message(gngdt_pb2.LearnerStatus, message))


def encode_frame_ack(**fields_: Any) -> gngdt_pb2.FrameAck:
    """``gngdt.FrameAck`` from keyword fields named as in :class:`FrameAckInfo`."""
    return _info_to_message(FrameAckInfo, gngdt_pb2.FrameAck, fields_)


def decode_frame_ack(message: gngdt_pb2.FrameAck | bytes) -> FrameAckInfo:
    """Decode a ``gngdt.FrameAck``."""
    return _message_to_info(FrameAckInfo, parse_message(gngdt_pb2.FrameAck, message))


def encode_stream_end(**fields_: Any) -> gngdt_pb2.StreamEnd:
    """``gngdt.StreamEnd`` from keyword fields named as in :class:`StreamEndInfo`."""
    return _info_to_message(StreamEndInfo, gngdt_pb2.StreamEnd, fields_)


def decode_stream_end(message: gngdt_pb2.StreamEnd | bytes) -> StreamEndInfo:
    """Decode a ``gngdt.StreamEnd``."""
    return _message_to_info(StreamEndInfo, parse_message(gngdt_pb2.StreamEnd, message))
