"""The Foxglove server's client connections, watched from outside the SDK.

``foxglove-sdk`` 0.30 queues up to ``message_backlog_size`` messages per client (a copy each)
and has no API to count, refuse or drop clients: 40 clients that never read grew a logger from
257 MB to 2.7 GB. `ClientGuard` finds the server's connections among this process's own sockets
(``/proc/self/fd``: a socket whose local port is the server's and that has a peer), and with a
duplicate of its descriptor (never the SDK's own, so a descriptor reused meanwhile is never
touched) reads its TCP state and, when needed, shuts it down: the SDK then sees the connection
end and frees the client's queue.

- a client cap: beyond ``max_clients`` connections the newest are dropped, each said once;
- a client too slow: one that has had data waiting in its socket and acknowledged none of it
  for ``stall_s`` is dropped, said once;
- memory back: when clients leave, the free pages are given back (`gngdt.io.memory`).

Linux only (``/proc``, ``TCP_INFO``); elsewhere the guard says once that it cannot watch.
"""

from __future__ import annotations

import fcntl
import logging
import os
import socket
import struct
import sys
import termios
import time
from dataclasses import dataclass
from pathlib import Path

from gngdt.io.memory import TrimPacer

__all__ = ["STALL_SECONDS", "ClientGuard"]

log = logging.getLogger(__name__)

#: a client with data waiting that acknowledges nothing for this long is too slow: dropped
STALL_SECONDS = 5.0
#: struct tcp_info (linux/tcp.h): tcpi_bytes_acked, a u64 at byte 120 (Linux 4.2 and later)
_BYTES_ACKED = struct.Struct("=Q")
_BYTES_ACKED_OFFSET = 120
_TCP_INFO_SIZE = 232


@dataclass
class _Client:
    """One connection: when it was first seen, its acknowledged bytes, when it last made
    progress (or had nothing waiting)."""

    first_seen: float
    bytes_acked: int
    progress_at: float


def _server_connections(port: int) -> list[tuple[tuple, socket.socket]]:
    """(peer address, duplicate) of this process's TCP connections on local ``port`` (the
    caller closes the duplicates)."""
    found = []
    for name in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{name}").startswith("socket:"):
                continue
            duplicate = socket.socket(fileno=os.dup(int(name)))
        except OSError:  # closed meanwhile
            continue
        try:
            if (duplicate.family in (socket.AF_INET, socket.AF_INET6)
                    and duplicate.type == socket.SOCK_STREAM
                    and duplicate.getsockname()[1] == port):
                found.append((duplicate.getpeername(), duplicate))  # a listener: OSError
                continue
        except OSError:
            pass
        duplicate.close()
    return found


def _progress(connection: socket.socket) -> tuple[int, int]:
    """(bytes acknowledged by the client so far, bytes waiting in the socket to go or be
    acknowledged)."""
    info = connection.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, _TCP_INFO_SIZE)
    acked = 0
    if len(info) >= _BYTES_ACKED_OFFSET + 8:
        (acked,) = _BYTES_ACKED.unpack_from(info, _BYTES_ACKED_OFFSET)
    waiting = struct.unpack("i", fcntl.ioctl(connection.fileno(), termios.TIOCOUTQ,
                                             b"\0" * 4))[0]
    return acked, waiting


class ClientGuard:
    """Watches the connections of the Foxglove server on ``port`` (see the module docstring);
    `poll` every half second or so."""

    def __init__(self, port: int, max_clients: int, stall_s: float = STALL_SECONDS) -> None:
        self.port = port
        self.max_clients = max_clients
        self.stall_s = stall_s
        self.available = sys.platform.startswith("linux") and Path("/proc/self/fd").is_dir()
        self._clients: dict[tuple, _Client] = {}
        #: peers shut down, until the SDK has closed their connection
        self._shut: set[tuple] = set()
        #: every peer connected at the last poll
        self._connected: set[tuple] = set()
        self._trim = TrimPacer()
        #: clients dropped for being too many / too slow
        self.refused = 0
        self.dropped_slow = 0
        if not self.available:
            log.warning("Foxglove: this system cannot be watched for slow or surplus clients "
                        "(Linux only); each may queue up to its backlog")

    def poll(self, now: float | None = None) -> None:
        if not self.available:
            return
        now = time.monotonic() if now is None else now
        connections = _server_connections(self.port)
        try:
            seen = self._watch(connections, now)
        finally:
            for _, connection in connections:
                connection.close()
        for peer in set(self._clients) - seen:
            del self._clients[peer]
        connected = {peer for peer, _ in connections}
        if self._connected - connected:  # the SDK let clients go: their queues are freed
            self._trim.soon()
        self._connected = connected
        self._trim.poll()

    def _drop(self, peer: tuple, connection: socket.socket) -> None:
        self._shut.add(peer)
        _shut(connection)

    def _watch(self, connections: list[tuple[tuple, socket.socket]], now: float) -> set[tuple]:
        """Drop the stalled and surplus connections; the peers still connected."""
        kept: list[tuple[float, tuple, socket.socket]] = []
        self._shut &= {peer for peer, _ in connections}  # those the SDK closed are forgotten
        for peer, connection in connections:
            if peer in self._shut:
                continue
            try:
                acked, waiting = _progress(connection)
            except OSError:
                continue
            client = self._clients.setdefault(peer, _Client(now, acked, now))
            if acked != client.bytes_acked or waiting == 0:
                client.bytes_acked, client.progress_at = acked, now
            if now - client.progress_at > self.stall_s:
                self.dropped_slow += 1
                log.warning("Foxglove client %s read nothing for %.0f s while %d bytes waited "
                            "for it: dropped (too slow)", _address(peer),
                            now - client.progress_at, waiting)
                self._drop(peer, connection)
                continue
            kept.append((client.first_seen, peer, connection))
        kept.sort(key=lambda item: item[0])
        for _, peer, connection in kept[self.max_clients:]:
            self.refused += 1
            log.warning("Foxglove client %s refused: %d clients connected, at most %d "
                        "(--foxglove-max-clients)", _address(peer), len(kept),
                        self.max_clients)
            self._drop(peer, connection)
        return {peer for _, peer, _ in kept[:self.max_clients]}


def _address(peer: tuple) -> str:
    host, port = peer[0], peer[1]
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def _shut(connection: socket.socket) -> None:
    """End the connection for the SDK too (its own descriptor stays its to close)."""
    try:
        connection.shutdown(socket.SHUT_RDWR)
    except OSError:  # gone meanwhile
        pass
