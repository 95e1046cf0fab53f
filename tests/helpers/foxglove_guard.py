"""The Foxglove client guard (`gngdt.io.outputs.foxglove_clients.ClientGuard`) on a bare server,
for the tests: waiting until the SDK has let a dropped client go, and the memory total played
out in a process of its own (``python -m helpers.foxglove_guard``)."""

from __future__ import annotations

import json
import socket
import time
from typing import Any


def wait_until_the_server_closed(guard: Any, client: socket.socket,
                                 timeout_s: float = 20.0) -> None:
    """Poll ``guard`` until the SDK has closed its end of ``client``'s connection (its queue is
    then freed). Reading the client's socket to its end instead took ~100 s: the kernel's
    buffers of a long-stalled connection drain slowly."""
    peer = client.getsockname()[:2]
    deadline = time.monotonic() + timeout_s
    while peer in {address[:2] for address in guard.connected}:
        assert time.monotonic() < deadline, "the server kept the dropped connection"
        time.sleep(0.01)
        guard.poll()


def over_the_total(total_bytes: float = 2e6, timeout_s: float = 30.0) -> dict[str, Any]:
    """A server whose clients may hold ``total_bytes`` together (the stall time never reached),
    a client that reads nothing and one that reads, 1 MB messages until the guard drops one
    for the memory held: what it dropped, the held bytes it saw, whether the reader was still
    served after.

    The guard measures its own process's resident memory, so this is meant for a fresh
    interpreter, as a logger is: in a test runner's process, queues may be carved out of
    memory freed by earlier tests and never show."""
    from hostile_doors import stalled_foxglove_client

    from gngdt.io.outputs.foxglove import FoxgloveServer
    from gngdt.io.outputs.foxglove_clients import ClientGuard
    from helpers.foxglove_client import FoxgloveClient

    server = FoxgloveServer("127.0.0.1", 0, backlog=8)
    guard = ClientGuard(server.port, max_clients=8, stall_s=3600.0, total_bytes=total_bytes)
    held: list[int] = []
    served_after = False
    try:
        channel = server.channel("/camera/depth", "foxglove.RawImage")
        stalled = stalled_foxglove_client(server.port)
        with FoxgloveClient(f"ws://127.0.0.1:{server.port}") as reader:
            deadline = time.monotonic() + timeout_s
            while guard.dropped_for_memory == 0 and time.monotonic() < deadline:
                channel.log(bytes(1_000_000), log_time=time.time_ns())
                while reader.receive(0.02) is not None:
                    pass
                guard.poll()
                held.append(guard.held_bytes())
            if guard.dropped_for_memory:
                wait_until_the_server_closed(guard, stalled)
                channel.log(bytes(1000), log_time=time.time_ns())
                served_after = reader.receive(5.0) is not None
        stalled.close()
    finally:
        server.stop()
    return {"dropped_for_memory": guard.dropped_for_memory,
            "dropped_slow": guard.dropped_slow, "refused": guard.refused,
            "messages": len(held), "held_mb_max": max(held, default=0) / 1e6,
            "served_after": served_after}


if __name__ == "__main__":
    print(json.dumps(over_the_total()))
