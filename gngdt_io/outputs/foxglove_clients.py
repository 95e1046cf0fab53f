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
- a total in bytes: what the clients hold together is this process's resident memory over what
  it was with no client connected. Past ``total_bytes``, the client furthest behind (data
  waiting, nothing acknowledged for ``MEMORY_STALL_SECONDS``) is dropped, said, one every
  ``MEMORY_DROP_PAUSE_S`` while the total stays over (its queue is freed by the SDK's thread,
  then given back). `over_total` is cheap enough to ask before every large message (the
  server holds large ones back meanwhile);
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

from gngdt.io.memory import TrimPacer, resident_bytes

__all__ = ["STALL_SECONDS", "ClientGuard"]

log = logging.getLogger(__name__)

#: a client with data waiting that acknowledges nothing for this long is too slow: dropped
STALL_SECONDS = 5.0
#: over the total, only a client that has acknowledged nothing this long while data waited for it
#: is dropped (one reading, even slowly, acknowledges within a poll or two)
MEMORY_STALL_SECONDS = 0.5
#: over the total, one client is dropped at most this often: the memory of the last one takes
#: that long to be freed and given back
MEMORY_DROP_PAUSE_S = 0.3
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
    """(peer address, duplicate) of this process's TCP connections on local ``port``, each
    once (the caller closes the duplicates)."""
    found = []
    #: descriptors this scan opened: the listing holds the number of the descriptor that read
    #: it, closed by now and taken by the first duplicate kept; read again, it is that
    #: connection a second time (a client within the cap was refused as its own surplus)
    ours: set[int] = set()
    for name in os.listdir("/proc/self/fd"):
        if int(name) in ours:
            continue
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
                ours.add(duplicate.fileno())
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

    def __init__(self, port: int, max_clients: int, stall_s: float = STALL_SECONDS,
                 total_bytes: float | None = None) -> None:
        self.port = port
        self.max_clients = max_clients
        self.stall_s = stall_s
        self.total_bytes = total_bytes
        self.available = sys.platform.startswith("linux") and Path("/proc/self/fd").is_dir()
        self._clients: dict[tuple, _Client] = {}
        #: peers shut down, until the SDK has closed their connection
        self._shut: set[tuple] = set()
        #: every peer connected at the last poll
        self._connected: set[tuple] = set()
        self._trim = TrimPacer(min_interval_s=MEMORY_DROP_PAUSE_S)
        #: this process's resident bytes with no client connected (the lowest seen since)
        self._resident_alone = resident_bytes()
        #: when the total was last found over (a client dropped if one was behind enough)
        self._memory_checked_at = -MEMORY_DROP_PAUSE_S
        #: clients dropped for being too many / too slow / holding more than the total
        self.refused = 0
        self.dropped_slow = 0
        self.dropped_for_memory = 0
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
        resident = resident_bytes()
        if resident is not None and self._resident_alone is not None and (
                not connected or resident < self._resident_alone):
            self._resident_alone = resident

    @property
    def connected(self) -> set[tuple]:
        """The peers (address, port) of the server's connections at the last `poll`."""
        return set(self._connected)

    def held_bytes(self) -> int:
        """What the clients hold now, as this process's resident memory over what it was with
        none connected (0 where that cannot be read)."""
        resident = resident_bytes()
        if resident is None or self._resident_alone is None:
            return 0
        return max(0, resident - self._resident_alone)

    def over_total(self) -> bool:
        """Whether the clients hold more than ``total_bytes`` (a few microseconds: ask it
        before every large message)."""
        return (self.available and self.total_bytes is not None
                and self.held_bytes() > self.total_bytes)

    def drop_due(self, now: float | None = None) -> bool:
        """Whether the clients hold more than ``total_bytes`` and `poll` would act on it now
        (drop the client furthest behind, give memory back)."""
        now = time.monotonic() if now is None else now
        return now - self._memory_checked_at >= MEMORY_DROP_PAUSE_S and self.over_total()

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
        kept = kept[:self.max_clients]
        if self.drop_due(now):
            self._memory_checked_at = now
            self._trim.soon()  # what the queues drained meanwhile, too
            behind = self._furthest_behind(kept, now)
            if behind is not None:
                self.dropped_for_memory += 1
                peer, connection = behind
                log.warning("Foxglove client %s dropped: the clients hold %.0f MB, more than "
                            "%.0f MB (--foxglove-total-mb), and it was furthest behind (nothing "
                            "read for %.1f s)", _address(peer), self.held_bytes() / 1e6,
                            self.total_bytes / 1e6, now - self._clients[peer].progress_at)
                self._drop(peer, connection)
                kept = [item for item in kept if item[1] != peer]
        return {peer for _, peer, _ in kept}

    def _furthest_behind(self, kept: list[tuple[float, tuple, socket.socket]],
                         now: float) -> tuple[tuple, socket.socket] | None:
        """(peer, connection) of the client longest without progress, if that is at least
        ``MEMORY_STALL_SECONDS``."""
        stalled = [(self._clients[peer].progress_at, peer, connection)
                   for _, peer, connection in kept
                   if now - self._clients[peer].progress_at >= MEMORY_STALL_SECONDS]
        if not stalled:
            return None
        _, peer, connection = min(stalled, key=lambda item: item[0])
        return peer, connection


def _address(peer: tuple) -> str:
    host, port = peer[0], peer[1]
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def _shut(connection: socket.socket) -> None:
    """End the connection for the SDK too (its own descriptor stays its to close)."""
    try:
        connection.shutdown(socket.SHUT_RDWR)
    except OSError:  # gone meanwhile
        pass
