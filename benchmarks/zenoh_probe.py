"""A zenoh client for tests that run where the test process cannot reach (another network
namespace): it reports what it sees as JSON lines.

    python benchmarks/zenoh_probe.py watch ENDPOINT OUT.jsonl  # topologies, liveliness; to SIGINT
    python benchmarks/zenoh_probe.py query ENDPOINT KEY        # a late joiner's get, as JSON
    python benchmarks/zenoh_probe.py count ENDPOINT OUT.json   # bytes per topic; to SIGINT

``watch`` writes ``{"ev": "topology", "camera", "sequence", "capture_ns", "received_ns",
"nodes"}`` per topology, ``{"ev": "objects", ...}`` per objects message and ``{"ev":
"alive"/"gone", "key"}`` per liveliness change; times are wall-clock nanoseconds (one kernel:
comparable across namespaces). ``count`` subscribes to ``gngdt/**`` and writes ``{key:
[samples, payload bytes]}`` when stopped.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
from pathlib import Path

from gngdt.schemas.topology import decode_topology
from gngdt.schemas.wire import ALL_KEYS, FrameStamp
from gngdt.services.plumbing.session import client_config, open_config


def watch(endpoint: str, out: Path) -> None:
    import zenoh

    lock = threading.Lock()
    output = open(out, "a", buffering=1)  # open while the session lives

    def write(**record: object) -> None:
        with lock:
            output.write(json.dumps(record) + "\n")

    def on_topology(sample: zenoh.Sample) -> None:
        received_ns = time.time_ns()
        stamp = FrameStamp.from_attachment(sample.attachment.to_bytes())
        topology = decode_topology(sample.payload.to_bytes())
        write(ev="topology", camera=str(sample.key_expr).split("/")[1], sequence=stamp.sequence,
              capture_ns=stamp.capture_time_ns, received_ns=received_ns,
              nodes=topology.node_count)

    def on_objects(sample: zenoh.Sample) -> None:
        stamp = FrameStamp.from_attachment(sample.attachment.to_bytes())
        write(ev="objects", camera=str(sample.key_expr).split("/")[1], sequence=stamp.sequence,
              capture_ns=stamp.capture_time_ns, received_ns=time.time_ns(),
              size=len(sample.payload))

    def on_token(sample: zenoh.Sample) -> None:
        alive = sample.kind == zenoh.SampleKind.PUT
        write(ev="alive" if alive else "gone", key=str(sample.key_expr), t=time.time_ns())

    session = open_config(client_config([endpoint]), wait_s=30.0)
    declared = [session.declare_subscriber("gngdt/*/topology", on_topology),
                session.declare_subscriber("gngdt/*/objects", on_objects),
                session.liveliness().declare_subscriber(ALL_KEYS, on_token, history=True)]
    write(ev="ready", t=time.time_ns())
    wait_for_stop()
    for entity in declared:
        entity.undeclare()
    session.close()
    output.close()


def wait_for_stop() -> None:
    """Return at SIGINT or SIGTERM."""
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    while not stop.wait(0.2):
        pass


def count(endpoint: str, out: Path) -> None:
    lock = threading.Lock()
    totals: dict[str, list[int]] = {}

    def on_sample(sample) -> None:
        with lock:
            total = totals.setdefault(str(sample.key_expr), [0, 0])
            total[0] += 1
            total[1] += len(sample.payload)

    session = open_config(client_config([endpoint]), wait_s=30.0)
    subscriber = session.declare_subscriber(ALL_KEYS, on_sample)
    print("READY", flush=True)
    wait_for_stop()
    subscriber.undeclare()
    session.close()
    with lock:
        out.write_text(json.dumps(totals))


def query(endpoint: str, key: str) -> None:
    started = time.monotonic()
    session = open_config(client_config([endpoint]), wait_s=30.0)
    opened = time.monotonic()
    replies = [reply.ok for reply in session.get(key, timeout=10.0) if reply.ok is not None]
    answered = time.monotonic()
    nodes = [decode_topology(sample.payload.to_bytes()).node_count
             for sample in replies]
    session.close()
    print(json.dumps({"replies": len(replies), "nodes": nodes,
                      "open_ms": (opened - started) * 1e3, "get_ms": (answered - opened) * 1e3}))


if __name__ == "__main__":
    if sys.argv[1] == "watch":
        watch(sys.argv[2], Path(sys.argv[3]))
    elif sys.argv[1] == "count":
        count(sys.argv[2], Path(sys.argv[3]))
    else:
        query(sys.argv[2], sys.argv[3])
