import datetime

from google.protobuf import timestamp_pb2 as _timestamp_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class PackedArray(_message.Message):
    __slots__ = ("dtype", "shape", "data")
    DTYPE_FIELD_NUMBER: _ClassVar[int]
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    dtype: str
    shape: _containers.RepeatedScalarFieldContainer[int]
    data: bytes
    def __init__(self, dtype: _Optional[str] = ..., shape: _Optional[_Iterable[int]] = ..., data: _Optional[bytes] = ...) -> None: ...

class EdgeSet(_message.Message):
    __slots__ = ("property", "pairs")
    PROPERTY_FIELD_NUMBER: _ClassVar[int]
    PAIRS_FIELD_NUMBER: _ClassVar[int]
    property: str
    pairs: PackedArray
    def __init__(self, property: _Optional[str] = ..., pairs: _Optional[_Union[PackedArray, _Mapping]] = ...) -> None: ...

class Clustering(_message.Message):
    __slots__ = ("name", "labels", "cluster_count", "cluster_ids")
    NAME_FIELD_NUMBER: _ClassVar[int]
    LABELS_FIELD_NUMBER: _ClassVar[int]
    CLUSTER_COUNT_FIELD_NUMBER: _ClassVar[int]
    CLUSTER_IDS_FIELD_NUMBER: _ClassVar[int]
    name: str
    labels: PackedArray
    cluster_count: int
    cluster_ids: PackedArray
    def __init__(self, name: _Optional[str] = ..., labels: _Optional[_Union[PackedArray, _Mapping]] = ..., cluster_count: _Optional[int] = ..., cluster_ids: _Optional[_Union[PackedArray, _Mapping]] = ...) -> None: ...

class Topology(_message.Message):
    __slots__ = ("timestamp", "frame_sequence", "steps", "frame_id", "positions", "colors", "normals", "errors", "edges", "clusterings", "quantization_error", "node_ids", "settled")
    class QuantizationErrorEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    FRAME_SEQUENCE_FIELD_NUMBER: _ClassVar[int]
    STEPS_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    COLORS_FIELD_NUMBER: _ClassVar[int]
    NORMALS_FIELD_NUMBER: _ClassVar[int]
    ERRORS_FIELD_NUMBER: _ClassVar[int]
    EDGES_FIELD_NUMBER: _ClassVar[int]
    CLUSTERINGS_FIELD_NUMBER: _ClassVar[int]
    QUANTIZATION_ERROR_FIELD_NUMBER: _ClassVar[int]
    NODE_IDS_FIELD_NUMBER: _ClassVar[int]
    SETTLED_FIELD_NUMBER: _ClassVar[int]
    timestamp: _timestamp_pb2.Timestamp
    frame_sequence: int
    steps: int
    frame_id: str
    positions: PackedArray
    colors: PackedArray
    normals: PackedArray
    errors: PackedArray
    edges: _containers.RepeatedCompositeFieldContainer[EdgeSet]
    clusterings: _containers.RepeatedCompositeFieldContainer[Clustering]
    quantization_error: _containers.ScalarMap[str, float]
    node_ids: PackedArray
    settled: bool
    def __init__(self, timestamp: _Optional[_Union[datetime.datetime, _timestamp_pb2.Timestamp, _Mapping]] = ..., frame_sequence: _Optional[int] = ..., steps: _Optional[int] = ..., frame_id: _Optional[str] = ..., positions: _Optional[_Union[PackedArray, _Mapping]] = ..., colors: _Optional[_Union[PackedArray, _Mapping]] = ..., normals: _Optional[_Union[PackedArray, _Mapping]] = ..., errors: _Optional[_Union[PackedArray, _Mapping]] = ..., edges: _Optional[_Iterable[_Union[EdgeSet, _Mapping]]] = ..., clusterings: _Optional[_Iterable[_Union[Clustering, _Mapping]]] = ..., quantization_error: _Optional[_Mapping[str, float]] = ..., node_ids: _Optional[_Union[PackedArray, _Mapping]] = ..., settled: _Optional[bool] = ...) -> None: ...

class LearnerStatus(_message.Message):
    __slots__ = ("timestamp", "frame_sequence", "frame_id", "steps", "steps_per_second", "nodes", "frames_received", "frames_used", "frames_dropped", "malformed_messages", "latency_ms", "latency_p50_ms", "latency_p99_ms", "quantization_error", "cluster_counts", "settle_reason", "seen_nodes", "ghost_share", "ghost_distance_m", "nodes_forgotten", "frames_other_frame", "frames_pose_rejected", "pose_problem", "frame_budget_ms", "frame_steps", "frames_lost_tracking", "tracking", "settled", "frames_posed", "frames_lost_by_reason")
    class QuantizationErrorEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    class ClusterCountsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    class FramesLostByReasonEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    FRAME_SEQUENCE_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    STEPS_FIELD_NUMBER: _ClassVar[int]
    STEPS_PER_SECOND_FIELD_NUMBER: _ClassVar[int]
    NODES_FIELD_NUMBER: _ClassVar[int]
    FRAMES_RECEIVED_FIELD_NUMBER: _ClassVar[int]
    FRAMES_USED_FIELD_NUMBER: _ClassVar[int]
    FRAMES_DROPPED_FIELD_NUMBER: _ClassVar[int]
    MALFORMED_MESSAGES_FIELD_NUMBER: _ClassVar[int]
    LATENCY_MS_FIELD_NUMBER: _ClassVar[int]
    LATENCY_P50_MS_FIELD_NUMBER: _ClassVar[int]
    LATENCY_P99_MS_FIELD_NUMBER: _ClassVar[int]
    QUANTIZATION_ERROR_FIELD_NUMBER: _ClassVar[int]
    CLUSTER_COUNTS_FIELD_NUMBER: _ClassVar[int]
    SETTLE_REASON_FIELD_NUMBER: _ClassVar[int]
    SEEN_NODES_FIELD_NUMBER: _ClassVar[int]
    GHOST_SHARE_FIELD_NUMBER: _ClassVar[int]
    GHOST_DISTANCE_M_FIELD_NUMBER: _ClassVar[int]
    NODES_FORGOTTEN_FIELD_NUMBER: _ClassVar[int]
    FRAMES_OTHER_FRAME_FIELD_NUMBER: _ClassVar[int]
    FRAMES_POSE_REJECTED_FIELD_NUMBER: _ClassVar[int]
    POSE_PROBLEM_FIELD_NUMBER: _ClassVar[int]
    FRAME_BUDGET_MS_FIELD_NUMBER: _ClassVar[int]
    FRAME_STEPS_FIELD_NUMBER: _ClassVar[int]
    FRAMES_LOST_TRACKING_FIELD_NUMBER: _ClassVar[int]
    TRACKING_FIELD_NUMBER: _ClassVar[int]
    SETTLED_FIELD_NUMBER: _ClassVar[int]
    FRAMES_POSED_FIELD_NUMBER: _ClassVar[int]
    FRAMES_LOST_BY_REASON_FIELD_NUMBER: _ClassVar[int]
    timestamp: _timestamp_pb2.Timestamp
    frame_sequence: int
    frame_id: str
    steps: int
    steps_per_second: float
    nodes: int
    frames_received: int
    frames_used: int
    frames_dropped: int
    malformed_messages: int
    latency_ms: float
    latency_p50_ms: float
    latency_p99_ms: float
    quantization_error: _containers.ScalarMap[str, float]
    cluster_counts: _containers.ScalarMap[str, int]
    settle_reason: str
    seen_nodes: int
    ghost_share: float
    ghost_distance_m: float
    nodes_forgotten: int
    frames_other_frame: int
    frames_pose_rejected: int
    pose_problem: str
    frame_budget_ms: float
    frame_steps: int
    frames_lost_tracking: int
    tracking: str
    settled: bool
    frames_posed: int
    frames_lost_by_reason: _containers.ScalarMap[str, int]
    def __init__(self, timestamp: _Optional[_Union[datetime.datetime, _timestamp_pb2.Timestamp, _Mapping]] = ..., frame_sequence: _Optional[int] = ..., frame_id: _Optional[str] = ..., steps: _Optional[int] = ..., steps_per_second: _Optional[float] = ..., nodes: _Optional[int] = ..., frames_received: _Optional[int] = ..., frames_used: _Optional[int] = ..., frames_dropped: _Optional[int] = ..., malformed_messages: _Optional[int] = ..., latency_ms: _Optional[float] = ..., latency_p50_ms: _Optional[float] = ..., latency_p99_ms: _Optional[float] = ..., quantization_error: _Optional[_Mapping[str, float]] = ..., cluster_counts: _Optional[_Mapping[str, int]] = ..., settle_reason: _Optional[str] = ..., seen_nodes: _Optional[int] = ..., ghost_share: _Optional[float] = ..., ghost_distance_m: _Optional[float] = ..., nodes_forgotten: _Optional[int] = ..., frames_other_frame: _Optional[int] = ..., frames_pose_rejected: _Optional[int] = ..., pose_problem: _Optional[str] = ..., frame_budget_ms: _Optional[float] = ..., frame_steps: _Optional[int] = ..., frames_lost_tracking: _Optional[int] = ..., tracking: _Optional[str] = ..., settled: _Optional[bool] = ..., frames_posed: _Optional[int] = ..., frames_lost_by_reason: _Optional[_Mapping[str, int]] = ...) -> None: ...

class StreamEnd(_message.Message):
    __slots__ = ("timestamp", "frames_sent", "last_frame_sequence", "recording", "frame_id", "frames_refused", "frames_without_cloud", "warnings")
    class FramesRefusedEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    class FramesWithoutCloudEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    FRAMES_SENT_FIELD_NUMBER: _ClassVar[int]
    LAST_FRAME_SEQUENCE_FIELD_NUMBER: _ClassVar[int]
    RECORDING_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    FRAMES_REFUSED_FIELD_NUMBER: _ClassVar[int]
    FRAMES_WITHOUT_CLOUD_FIELD_NUMBER: _ClassVar[int]
    WARNINGS_FIELD_NUMBER: _ClassVar[int]
    timestamp: _timestamp_pb2.Timestamp
    frames_sent: int
    last_frame_sequence: int
    recording: str
    frame_id: str
    frames_refused: _containers.ScalarMap[str, int]
    frames_without_cloud: _containers.ScalarMap[str, int]
    warnings: _containers.RepeatedScalarFieldContainer[str]
    def __init__(self, timestamp: _Optional[_Union[datetime.datetime, _timestamp_pb2.Timestamp, _Mapping]] = ..., frames_sent: _Optional[int] = ..., last_frame_sequence: _Optional[int] = ..., recording: _Optional[str] = ..., frame_id: _Optional[str] = ..., frames_refused: _Optional[_Mapping[str, int]] = ..., frames_without_cloud: _Optional[_Mapping[str, int]] = ..., warnings: _Optional[_Iterable[str]] = ...) -> None: ...

class FrameAck(_message.Message):
    __slots__ = ("timestamp", "frame_sequence", "outcome", "problem")
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    FRAME_SEQUENCE_FIELD_NUMBER: _ClassVar[int]
    OUTCOME_FIELD_NUMBER: _ClassVar[int]
    PROBLEM_FIELD_NUMBER: _ClassVar[int]
    timestamp: _timestamp_pb2.Timestamp
    frame_sequence: int
    outcome: str
    problem: str
    def __init__(self, timestamp: _Optional[_Union[datetime.datetime, _timestamp_pb2.Timestamp, _Mapping]] = ..., frame_sequence: _Optional[int] = ..., outcome: _Optional[str] = ..., problem: _Optional[str] = ...) -> None: ...
