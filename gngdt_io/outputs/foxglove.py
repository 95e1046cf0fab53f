"""Serve gngdt's streams live to Foxglove: a Foxglove WebSocket server (``foxglove-sdk``) with
the same channels as ``--mcap`` (`gngdt.io.outputs.mcap`): ``/<cam>/color``, ``/<cam>/depth``,
``/<cam>/calibration``, ``/<cam>/points``, ``/<cam>/scene``, ``/<cam>/objects``, gngdt's own
topology, status and end of stream, and the camera poses on ``/tf``.

Every sample is forwarded as it arrived (its protobuf bytes, never re-encoded) on an SDK channel
declared with ``message_encoding="protobuf"`` and the message's ``FileDescriptorSet`` as schema,
``log_time`` the frame's capture time. Zenoh's callback only keeps the newest sample of each key;
a thread hands them to the server, so a slow client never blocks a subscriber.

What clients may cost is bounded in bytes (`gngdt.io.outputs.foxglove_clients`): each gets at
most ``--foxglove-backlog`` (8) queued messages, beyond which the SDK drops its oldest, and no
message larger than ``--foxglove-client-mb`` (48) over the backlog is sent (said once per
topic), so a client holds at most that many megabytes; all of them together hold at most
``--foxglove-total-mb`` (256: past it, the client furthest behind is dropped, said, and the
guard is asked before every message of a megabyte or more, so a loaded machine cannot outrun
it); at most ``--foxglove-max-clients`` (16) are served (a newer one is dropped, said); one that
has acknowledged nothing for ``STALL_SECONDS`` while data waited for it is dropped as too slow,
said; the memory of clients gone goes back to the system. Before: 40 clients that never read
took a logger from 257 MB to 2.7 GB, kept after they left.

Foxglove has no latched topics: a client that connects late would never get the calibration
(sent at start and on change) nor, once a recording has ended, anything at all. So each
channel's last message is sent again whenever the channel has been quiet for
``REPUBLISH_SECONDS`` and a client listens; what comes again carries its original time.

The server listens on loopback unless ``--bind`` says otherwise; a port in use is an error
before anything starts.
"""

from __future__ import annotations

import argparse
import logging
import socket
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gngdt.io.outputs.base import Output, split_bind
from gngdt.io.outputs.mcap import PROTOBUF_PREFIX, channel_topic, message_classes
from gngdt.schemas.wire import FrameStamp

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

DEFAULT_FOXGLOVE_PORT = 8765
#: messages queued per client before the SDK drops the oldest
DEFAULT_BACKLOG = 8
#: megabytes a client's queue may hold: no message larger than this over the backlog is sent
DEFAULT_CLIENT_MB = 48
#: megabytes all clients may hold together (the logger's memory over what it was without them)
DEFAULT_TOTAL_MB = 256
#: clients served at once
DEFAULT_MAX_CLIENTS = 16
#: a message this large or larger first asks the guard whether the clients hold too much
LARGE_MESSAGE_BYTES = 1_000_000
#: messages held back for the clients' memory are said at most this often
HELD_BACK_SAID_EVERY_S = 30.0
#: how often the clients are watched (`ClientGuard.poll`), seconds
GUARD_PERIOD_S = 0.1
#: a channel quiet this long gets its last message again (late clients, ended streams)
REPUBLISH_SECONDS = 1.0
#: distinct keys served at most (16 cameras of ~10 streams): garbage keys make no channels
MAX_KEYS = 256


def websocket_url(host: str, port: int) -> str:
    """The address a Foxglove client opens for a server listening on ``host:port``."""
    from gngdt.io.outputs.rerun_sinks import url_host

    return f"ws://{url_host(host)}:{port}"


#: how to open a Foxglove WebSocket in Foxglove (the desktop app, or app.foxglove.dev)
FOXGLOVE_STEPS = ("open it in Foxglove, the app or app.foxglove.dev: Open connection > Foxglove "
                  "WebSocket")


def check_bindable(host: str, port: int) -> None:
    """OSError naming ``host:port`` when a server could not listen there (a port in use, an
    address not of this machine); as the SDK's server does, with SO_REUSEADDR."""
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind((host, port))
    except OSError as error:
        raise OSError(f"cannot serve Foxglove on {host}:{port}: {error.strerror or error} "
                      "(choose another with --bind HOST:PORT)") from None


def file_descriptor_set(descriptor: Any) -> bytes:
    """Serialized ``FileDescriptorSet`` of a message type and every file it depends on,
    dependencies first (what MCAP and Foxglove take as a protobuf schema)."""
    from google.protobuf import descriptor_pb2

    files = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(file: Any) -> None:
        if file.name in seen:
            return
        seen.add(file.name)
        for dependency in file.dependencies:
            add(dependency)
        proto = descriptor_pb2.FileDescriptorProto()
        file.CopyToProto(proto)
        files.file.append(proto)

    add(descriptor.file)
    return files.SerializeToString()


class FoxgloveServer:
    """A Foxglove WebSocket server publishing pre-encoded protobuf messages, on a private
    ``foxglove.Context`` (its channels reach no other sink). ``port`` 0 picks a free one."""

    def __init__(self, host: str, port: int, backlog: int = DEFAULT_BACKLOG) -> None:
        import foxglove

        self._context = foxglove.Context()
        self._channels: dict[str, Any] = {}
        self._classes = message_classes()
        try:
            self._server = foxglove.start_server(
                name="gngdt", host=host, port=port, context=self._context,
                message_backlog_size=backlog)
        except RuntimeError as error:  # "FoxgloveError: Failed to bind port: ..."
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {error}") from None
        self.host = host
        self.port = self._server.port
        self.backlog = backlog

    @property
    def url(self) -> str:
        return websocket_url(self.host, self.port)

    def channel(self, topic: str, type_name: str) -> Any | None:
        """The channel of ``topic`` carrying ``type_name`` (advertised on first use); None when
        the type is unknown or the topic already carries another."""
        import foxglove

        channel = self._channels.get(topic)
        if channel is None:
            message_class = self._classes.get(type_name)
            if message_class is None:
                return None
            schema = foxglove.Schema(name=type_name, encoding="protobuf",
                                     data=file_descriptor_set(message_class.DESCRIPTOR))
            channel = self._channels[topic] = foxglove.Channel(
                topic, schema=schema, message_encoding="protobuf", context=self._context)
        return channel if channel.schema_name() == type_name else None

    def stop(self) -> None:
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()
        self._server.stop()


class _Registrations(logging.Handler):
    """Calls ``on_registration`` when the SDK logs that a client connected (its INFO line
    "Registered client ...", on the SDK's thread): the client guard then runs at once instead
    of within ``GUARD_PERIOD_S``, before the client has subscribed to anything. Only a hint:
    with the SDK's INFO lines off (--log-level WARNING) the guard's period still holds."""

    LOGGER = "foxglove.websocket.server"

    def __init__(self, on_registration: Any) -> None:
        super().__init__(logging.INFO)
        self._on_registration = on_registration
        logging.getLogger(self.LOGGER).addHandler(self)

    def emit(self, record: logging.LogRecord) -> None:
        if str(record.msg).startswith("Registered client"):
            self._on_registration()

    def close(self) -> None:
        logging.getLogger(self.LOGGER).removeHandler(self)
        super().close()


@dataclass
class _Latest:
    """The newest sample of one key, and when it was last sent (monotonic s; 0: not yet)."""

    topic: str
    type_name: str
    payload: bytes
    log_time_ns: int
    sent_at: float = 0.0


class FoxgloveOutput(Output):
    """``--foxglove``: every gngdt stream, live, on a Foxglove WebSocket server."""

    raw = True

    def __init__(self, host: str, port: int, backlog: int = DEFAULT_BACKLOG,
                 republish_s: float = REPUBLISH_SECONDS, client_mb: float = DEFAULT_CLIENT_MB,
                 max_clients: int = DEFAULT_MAX_CLIENTS,
                 total_mb: float = DEFAULT_TOTAL_MB) -> None:
        from gngdt.io.outputs.foxglove_clients import ClientGuard

        self.server = FoxgloveServer(host, port, backlog)
        self.guard = ClientGuard(self.server.port, max_clients, total_bytes=total_mb * 1e6)
        self._guard_due = False
        self._registrations = _Registrations(self._on_registration)
        #: largest message sent: a client's backlog of them fits in ``client_mb``
        self.max_message_bytes = int(client_mb * 1e6 / backlog)
        self._too_large: set[str] = set()
        self.republish_s = republish_s
        self._latest: dict[str, _Latest] = {}
        self._new: set[str] = set()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closing = False
        self.sent = self.replaced = self.skipped = self.republished = self.held_back = 0
        self._held_back_said_at = -HELD_BACK_SAID_EVERY_S
        self._thread = threading.Thread(target=self._run, name="foxglove", daemon=True)
        self._thread.start()

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        group = parser.add_argument_group("Foxglove (--foxglove)")
        group.add_argument("--foxglove", action="store_true",
                           help="also serve every gngdt stream live to Foxglove (a Foxglove "
                           "WebSocket, the same channels as --mcap) at --bind's address, port "
                           f"{DEFAULT_FOXGLOVE_PORT} unless --bind names one")
        group.add_argument("--foxglove-backlog", type=int, default=DEFAULT_BACKLOG, metavar="N",
                           help="messages queued per Foxglove client; a client reading slower "
                           f"loses its oldest (default {DEFAULT_BACKLOG})")
        group.add_argument("--foxglove-client-mb", type=float, default=DEFAULT_CLIENT_MB,
                           metavar="MB", help="megabytes a Foxglove client's queue may hold: "
                           "no message larger than this over --foxglove-backlog is sent "
                           f"(default {DEFAULT_CLIENT_MB:g})")
        group.add_argument("--foxglove-total-mb", type=float, default=DEFAULT_TOTAL_MB,
                           metavar="MB", help="megabytes all Foxglove clients may hold "
                           "together (the logger's memory over what it was without them); past "
                           "it the client furthest behind is dropped "
                           f"(default {DEFAULT_TOTAL_MB:g})")
        group.add_argument("--foxglove-max-clients", type=int, default=DEFAULT_MAX_CLIENTS,
                           metavar="N", help="Foxglove clients served at once; a newer one is "
                           f"dropped (default {DEFAULT_MAX_CLIENTS})")

    @classmethod
    def check_args(cls, args: argparse.Namespace) -> None:
        if args.foxglove:
            check_bindable(*split_bind(args.bind, DEFAULT_FOXGLOVE_PORT))
        for option, default, low in (("backlog", DEFAULT_BACKLOG, 1),
                                     ("client_mb", DEFAULT_CLIENT_MB, 1),
                                     ("total_mb", DEFAULT_TOTAL_MB, 1),
                                     ("max_clients", DEFAULT_MAX_CLIENTS, 1)):
            value = getattr(args, f"foxglove_{option}", default)
            if not low <= value <= 1e6:  # also NaN
                raise ValueError(f"--foxglove-{option.replace('_', '-')} must be {low} to "
                                 f"1,000,000, got {value}")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> FoxgloveOutput | None:
        if not args.foxglove:
            return None
        host, port = split_bind(args.bind, DEFAULT_FOXGLOVE_PORT)
        return cls(host, port, args.foxglove_backlog, client_mb=args.foxglove_client_mb,
                   max_clients=args.foxglove_max_clients, total_mb=args.foxglove_total_mb)

    def describe(self) -> str:
        return f"serving Foxglove at {self.server.url} ({FOXGLOVE_STEPS} > {self.server.url})"

    def receive(self, sample: zenoh.Sample) -> None:
        key, encoding = str(sample.key_expr), str(sample.encoding)
        topic = channel_topic(key)
        if topic is None or not encoding.startswith(PROTOBUF_PREFIX):
            self.skipped += 1
            return
        attachment = sample.attachment
        try:
            log_time = FrameStamp.from_attachment(
                attachment.to_bytes() if attachment is not None else None).capture_time_ns
        except ValueError:
            log_time = time.time_ns()
        latest = _Latest(topic, encoding.removeprefix(PROTOBUF_PREFIX).split(";")[0],
                         sample.payload.to_bytes(), log_time)
        with self._lock:
            if key not in self._latest and len(self._latest) >= MAX_KEYS:
                self.skipped += 1
                return
            if key in self._new:
                self.replaced += 1  # the thread had not sent the previous one yet
            self._latest[key] = latest
            self._new.add(key)
        self._wake.set()

    def _run(self) -> None:
        watched = 0.0
        while not self._closing:
            self._wake.wait(min(GUARD_PERIOD_S, self.republish_s))
            self._wake.clear()
            if self._guard_due or time.monotonic() - watched >= GUARD_PERIOD_S:
                self._guard_due = False
                self.guard.poll()
                watched = time.monotonic()
            with self._lock:
                new = [self._latest[key] for key in self._new]
                self._new.clear()
                quiet = [item for item in self._latest.values() if item.sent_at
                         and time.monotonic() - item.sent_at >= self.republish_s]
            for item in new:
                self._send(item)
            for item in quiet:
                if self._send(item, only_if_listened=True):
                    self.republished += 1

    def _on_registration(self) -> None:
        """A client connected: watch the clients now, before it is sent anything."""
        self._guard_due = True
        self._wake.set()

    def _send(self, item: _Latest, only_if_listened: bool = False) -> bool:
        channel = self.server.channel(item.topic, item.type_name)
        if channel is None or len(item.payload) > self.max_message_bytes:
            self.skipped += 1
            if channel is not None and item.topic not in self._too_large:
                self._too_large.add(item.topic)
                log.warning("Foxglove: %s messages of %.1f MB are not served: a client may "
                            "queue %d of them, at most %.0f MB (--foxglove-client-mb)",
                            item.topic, len(item.payload) / 1e6, self.server.backlog,
                            self.max_message_bytes * self.server.backlog / 1e6)
            return False
        item.sent_at = time.monotonic()
        if only_if_listened and not channel.has_sinks():
            return False
        if len(item.payload) >= LARGE_MESSAGE_BYTES and self.guard.over_total():
            self._hold_back(item)
            return False
        channel.log(item.payload, log_time=item.log_time_ns)
        self.sent += 1
        return True

    def _hold_back(self, item: _Latest) -> None:
        """The clients hold more than --foxglove-total-mb: ``item`` (large) is not sent, the
        guard acts now rather than at its next period (a loaded machine fills queues fast)."""
        self.held_back += 1
        now = time.monotonic()
        if now - self._held_back_said_at >= HELD_BACK_SAID_EVERY_S:
            self._held_back_said_at = now
            log.warning("Foxglove: the clients hold %.0f MB, more than %.0f MB "
                        "(--foxglove-total-mb): messages of a megabyte or more (%s) are held "
                        "back until their queues drain (%d so far; said at most every %.0f s)",
                        self.guard.held_bytes() / 1e6, self.guard.total_bytes / 1e6,
                        item.topic, self.held_back, HELD_BACK_SAID_EVERY_S)
        if self.guard.drop_due():
            self.guard.poll()

    def close(self) -> None:
        self._closing = True
        self._wake.set()
        self._thread.join()
        self._registrations.close()
        self.server.stop()
        log.info("Foxglove: %d messages sent (%d again for late clients), %d replaced by newer "
                 "ones before they were sent, %d skipped, %d held back for the clients' memory; "
                 "%d clients refused, %d dropped as too slow, %d for the memory they held",
                 self.sent, self.republished, self.replaced, self.skipped, self.held_back,
                 self.guard.refused, self.guard.dropped_slow,
                 self.guard.dropped_for_memory)
