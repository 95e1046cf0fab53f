"""A minimal Foxglove WebSocket client for the tests, independent of ``foxglove-sdk`` (whose
server is Rust): the ``websockets`` package and foxglove-schemas-protobuf for decoding.

Speaks the Foxglove WebSocket protocol (spec: foxglove/ws-protocol ``docs/spec.md``) over the
``websockets`` library, with the subprotocol ``foxglove.sdk.v1`` that ``foxglove-sdk`` servers
require (they answer HTTP 400 to ``foxglove.websocket.v1``; the messages are the same).

Server -> client frames used here:
- text ``{"op": "serverInfo", ...}`` first, then ``{"op": "advertise", "channels": [...]}``
  (per channel: ``id``, ``topic``, ``encoding``, ``schemaName``, ``schemaEncoding``, ``schema``;
  for protobuf the schema is a base64 ``FileDescriptorSet``), ``unadvertise``, ``status``;
- binary Message Data: ``0x01`` | uint32 LE subscription id | uint64 LE log time (ns) | payload.
Client -> server: ``{"op": "subscribe", "subscriptions": [{"id": n, "channelId": c}]}``.
"""

from __future__ import annotations

import base64
import importlib
import json
import logging
import struct
import time
from contextlib import ExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import Message
from websockets.sync.client import ClientConnection, connect

log = logging.getLogger(__name__)

SUBPROTOCOL = "foxglove.sdk.v1"
OP_MESSAGE_DATA = 0x01
_MESSAGE_DATA_HEADER = struct.Struct("<BIQ")  # opcode, subscription id, log time ns


@dataclass(frozen=True)
class AdvertisedChannel:
    """One channel from an ``advertise`` message."""

    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    schema: bytes


@dataclass(frozen=True)
class ReceivedMessage:
    """One Message Data frame, with the channel it belongs to."""

    channel: AdvertisedChannel
    subscription_id: int
    log_time_ns: int
    payload: bytes


def parse_message_data(frame: bytes) -> tuple[int, int, bytes]:
    """Split a binary Message Data frame into (subscription id, log time ns, payload)."""
    if len(frame) < _MESSAGE_DATA_HEADER.size:
        raise ValueError(f"binary frame of {len(frame)} bytes is too short")
    opcode, sub_id, log_time = _MESSAGE_DATA_HEADER.unpack_from(frame)
    if opcode != OP_MESSAGE_DATA:
        raise ValueError(f"not a Message Data frame (opcode {opcode:#04x})")
    return sub_id, log_time, bytes(frame[_MESSAGE_DATA_HEADER.size:])


def parse_channel(raw: dict[str, Any]) -> AdvertisedChannel:
    """An advertised channel; a protobuf schema is base64-decoded to FileDescriptorSet bytes."""
    schema_encoding = raw.get("schemaEncoding") or raw["encoding"]
    schema = raw.get("schema", "")
    data = base64.b64decode(schema) if schema_encoding == "protobuf" else schema.encode()
    return AdvertisedChannel(
        id=int(raw["id"]), topic=raw["topic"], encoding=raw["encoding"],
        schema_name=raw["schemaName"], schema_encoding=schema_encoding, schema=data,
    )


def foxglove_message_class(schema_name: str) -> type[Message]:
    """The ``foxglove-schemas-protobuf`` class for a schema name like ``foxglove.PointCloud``."""
    package, _, short = schema_name.rpartition(".")
    if package != "foxglove":
        raise KeyError(schema_name)
    module = importlib.import_module(f"foxglove_schemas_protobuf.{short}_pb2")
    return getattr(module, short)


def schema_message_class(channel: AdvertisedChannel) -> type[Message]:
    """A message class built from the channel's own advertised ``FileDescriptorSet``."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(channel.schema)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel.schema_name))


def decode(message: ReceivedMessage) -> Message:
    """Decode a protobuf payload: ``foxglove.*`` with foxglove-schemas-protobuf, others with
    the advertised schema."""
    channel = message.channel
    if channel.encoding != "protobuf":
        raise ValueError(f"{channel.topic}: encoding {channel.encoding!r} is not protobuf")
    try:
        cls = foxglove_message_class(channel.schema_name)
    except (KeyError, ImportError, AttributeError):
        cls = schema_message_class(channel)
    return cls.FromString(message.payload)


class FoxgloveClient:
    """Connects, subscribes to channels as they are advertised, and collects messages.

    Args:
        url: ``ws://host:port``.
        subscribe_all: subscribe to every advertised channel automatically.
        open_timeout: seconds allowed for the TCP connect + WebSocket handshake.
        subprotocol: offered in the handshake.
    """

    def __init__(
        self,
        url: str,
        *,
        subscribe_all: bool = True,
        open_timeout: float = 5.0,
        subprotocol: str = SUBPROTOCOL,
    ) -> None:
        self.url = url
        self.subscribe_all = subscribe_all
        self.open_timeout = open_timeout
        self.subprotocol = subprotocol
        self.server_info: dict[str, Any] = {}
        self.channels: dict[int, AdvertisedChannel] = {}
        self._ws: ClientConnection | None = None
        self._stack = ExitStack()
        self._subscriptions: dict[int, int] = {}  # subscription id -> channel id
        self._next_sub = 1

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def connect(self) -> None:
        """Open the WebSocket (raises ``websockets.exceptions.InvalidStatus`` on HTTP 400)."""
        self._ws = self._stack.enter_context(
            connect(
                self.url,
                subprotocols=[self.subprotocol],  # type: ignore[list-item]
                open_timeout=self.open_timeout,
                max_size=None,  # images and clouds exceed the 1 MiB default
                compression=None,
            )
        )

    def close(self) -> None:
        """Close the connection."""
        self._ws = None
        self._stack.close()

    def subscribe(self, channel_ids: list[int]) -> None:
        """Subscribe to channels (one new subscription id each)."""
        assert self._ws is not None
        subs = []
        for cid in channel_ids:
            if cid in self._subscriptions.values():
                continue
            self._subscriptions[self._next_sub] = cid
            subs.append({"id": self._next_sub, "channelId": cid})
            self._next_sub += 1
        if subs:
            self._ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def _on_text(self, text: str) -> None:
        msg = json.loads(text)
        op = msg.get("op")
        if op == "serverInfo":
            self.server_info = msg
        elif op == "advertise":
            new = [parse_channel(c) for c in msg["channels"]]
            self.channels.update({c.id: c for c in new})
            if self.subscribe_all:
                self.subscribe([c.id for c in new])
        elif op == "unadvertise":
            for cid in msg["channelIds"]:
                self.channels.pop(cid, None)
        elif op == "status":
            log.info("server status %s: %s", msg.get("level"), msg.get("message"))

    def receive(self, timeout: float) -> ReceivedMessage | None:
        """Handle frames until a Message Data frame arrives (returned) or ``timeout`` ends."""
        assert self._ws is not None
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                frame = self._ws.recv(timeout=left)
            except TimeoutError:
                return None
            if isinstance(frame, str):
                self._on_text(frame)
                continue
            sub_id, log_time, payload = parse_message_data(frame)
            cid = self._subscriptions.get(sub_id)
            if cid is None or cid not in self.channels:
                continue  # unsubscribed or unadvertised meanwhile
            return ReceivedMessage(self.channels[cid], sub_id, log_time, payload)
        return None
