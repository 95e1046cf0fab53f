"""Generic protobuf plumbing: parsing, timestamps and numpy arrays as ``gngdt.PackedArray``.

Every encoder of :mod:`schemas` takes ``timestamp_ns`` (int, nanoseconds since the epoch) and fills
the protobuf ``Timestamp``; decoders give nanoseconds back. Every decoder accepts the message or
its serialized ``bytes`` (what zenoh delivers) and raises :class:`MessageError` -- never another
exception type -- for anything malformed: undecodable bytes, unknown dtype strings, inconsistent
sizes, indices out of range. Sizes are validated before anything is allocated, so a hostile header
cannot make a decoder allocate gigabytes.

Arrays returned by :func:`unpack_array` are read-only views on the message bytes (zero-copy);
``.copy()`` them to modify.
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np
from google.protobuf.message import Message
from google.protobuf.timestamp_pb2 import Timestamp

import gngdt.schemas.gngdt_pb2 as gngdt_pb2

__all__ = [
    "NANOS_PER_SECOND",
    "PACKED_DTYPES",
    "MessageError",
    "little_endian",
    "ns_to_timestamp",
    "pack_array",
    "parse_message",
    "timestamp_to_ns",
    "unpack_array",
]

NANOS_PER_SECOND = 1_000_000_000

#: dtypes a PackedArray may carry (numpy names, always little-endian on the wire).
PACKED_DTYPES = frozenset(
    {"float32", "float64", "uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64"}
)

#: any protobuf message type (decoders return the type they are given)
MessageT = TypeVar("MessageT", bound=Message)


class MessageError(ValueError):
    """A payload is malformed: undecodable, inconsistent or out of the accepted limits."""


# --------------------------------------------------------------------------------------- generic
def parse_message(message_type: type[MessageT], data: MessageT | bytes) -> MessageT:
    """Return ``data`` as a ``message_type``: parsed if bytes, as it is if already that message."""
    if isinstance(data, message_type):
        return data
    if not isinstance(data, bytes | bytearray | memoryview):
        raise MessageError(
            f"expected bytes or {message_type.DESCRIPTOR.full_name}, got {type(data).__name__}"
        )
    try:
        return message_type.FromString(bytes(data))
    except Exception as error:  # DecodeError, invalid UTF-8, ... all mean the same here
        raise MessageError(
            f"cannot decode {message_type.DESCRIPTOR.full_name} ({len(data)} bytes): {error}"
        ) from error


def ns_to_timestamp(timestamp_ns: int, target: Timestamp | None = None) -> Timestamp:
    """Fill (or create) a protobuf ``Timestamp`` from integer nanoseconds."""
    timestamp_ns = int(timestamp_ns)
    target = Timestamp() if target is None else target
    target.seconds, target.nanos = divmod(timestamp_ns, NANOS_PER_SECOND)
    return target


def timestamp_to_ns(timestamp: Timestamp) -> int:
    """Integer nanoseconds of a protobuf ``Timestamp``."""
    return timestamp.seconds * NANOS_PER_SECOND + timestamp.nanos


def little_endian(dtype: np.dtype) -> np.dtype:
    """``dtype`` in little-endian byte order (the wire's), unchanged for single bytes."""
    return dtype.newbyteorder("<") if dtype.itemsize > 1 else dtype


# ---------------------------------------------------------------------------------- PackedArray
def pack_array(array: np.ndarray, dtype: np.typing.DTypeLike = None) -> gngdt_pb2.PackedArray:
    """Pack an array (cast to ``dtype`` if given) as little-endian C-order bytes with its shape."""
    array = np.asarray(array, dtype=dtype)
    if array.dtype.name not in PACKED_DTYPES:
        raise ValueError(f"pack_array: dtype {array.dtype} is not one of {sorted(PACKED_DTYPES)}")
    wire = np.ascontiguousarray(array, dtype=little_endian(array.dtype))
    return gngdt_pb2.PackedArray(
        dtype=array.dtype.name, shape=list(array.shape), data=wire.tobytes()
    )


def unpack_array(
    message: gngdt_pb2.PackedArray | bytes,
    *,
    dtype: np.typing.DTypeLike = None,
    ndim: int | None = None,
    max_elements: int | None = None,
    name: str = "array",
) -> np.ndarray:
    """Read-only array view of a PackedArray, validated before anything is allocated.

    dtype/ndim: required dtype and number of dimensions (``None`` accepts any).
    max_elements: upper bound on the number of elements. ``name`` appears in error messages.
    """
    message = parse_message(gngdt_pb2.PackedArray, message)
    if message.dtype not in PACKED_DTYPES:
        raise MessageError(f"{name}: unknown dtype {message.dtype!r}")
    wire_dtype = little_endian(np.dtype(message.dtype))
    if dtype is not None and np.dtype(dtype) != np.dtype(message.dtype):
        raise MessageError(f"{name}: dtype {message.dtype}, expected {np.dtype(dtype).name}")
    shape = tuple(int(size) for size in message.shape)
    if ndim is not None and len(shape) != ndim:
        raise MessageError(f"{name}: shape {shape} has {len(shape)} dimensions, expected {ndim}")
    elements = math.prod(shape)
    if max_elements is not None and elements > max_elements:
        raise MessageError(f"{name}: {elements} elements exceed the limit of {max_elements}")
    expected_bytes = elements * wire_dtype.itemsize
    if len(message.data) != expected_bytes:
        raise MessageError(
            f"{name}: {len(message.data)} bytes of data, shape {shape} {message.dtype} "
            f"needs {expected_bytes}"
        )
    return np.frombuffer(message.data, dtype=wire_dtype).reshape(shape)
