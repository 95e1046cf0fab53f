"""Back-pressure: a subscriber that never reads must not stall the pipeline. Images, clouds and
topologies are latest-wins (DROP: it loses stale ones); what must arrive (calibration, status,
end of stream) is BLOCK, and the router cuts such a client off after a second."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]

#: a client of the router subscribed to everything, whose callback never returns
NEVER_READS = """
import sys, time
from gngdt.services.plumbing.session import client_config, open_config
session = open_config(client_config([sys.argv[1]]), wait_s=30)
session.declare_subscriber("gngdt/**", lambda sample: time.sleep(3600))
print("subscribed", flush=True)
time.sleep(3600)
"""


@pytest.mark.timeout(120)
def test_a_subscriber_that_never_reads_stalls_neither_capture_nor_other_subscribers(
    router_endpoint: str, tabletop_recording: Path
) -> None:
    from gngdt.io.mcap.reader import read_frames
    from gngdt.schemas.status import decode_stream_end
    from gngdt.schemas.wire import FrameStamp
    from gngdt.services.capture import CapturePublisher, CloudOptions, FrameToCloud
    from gngdt.services.plumbing.session import client_config, open_config

    frames = list(read_frames(tabletop_recording))
    to_cloud = FrameToCloud(CloudOptions())
    clouds = [to_cloud(frame) for frame in frames]
    hostile = subprocess.Popen([sys.executable, "-c", NEVER_READS, router_endpoint],
                               cwd=REPO_ROOT, stdout=subprocess.PIPE, start_new_session=True)
    listener = open_config(client_config([router_endpoint]))
    config = client_config([router_endpoint])
    # the bytes themselves on the wire, as to a subscriber on another machine (on one machine
    # zenoh passes large payloads through shared memory, which only delays the stall)
    config.insert_json5("transport/shared_memory/enabled", "false")
    publisher_session = open_config(config)
    lock = threading.Lock()
    arrivals: list[float] = []
    ends: list = []

    def count(sample) -> None:
        with lock:
            arrivals.append(time.monotonic())

    try:
        assert hostile.stdout.readline().startswith(b"subscribed")
        listener.declare_subscriber("gngdt/camera/points", count)
        listener.declare_subscriber("gngdt/camera/eos", lambda sample: ends.append(
            decode_stream_end(sample.payload.to_bytes())))
        publisher = CapturePublisher(publisher_session, "camera")
        time.sleep(0.5)  # the subscriptions reached the router
        sent = 0
        started = time.monotonic()
        while time.monotonic() - started < 8.0:  # ~1.3 MB a frame: far beyond a link's buffers
            frame = frames[sent % len(frames)]
            publisher.publish_frame(frame, FrameStamp(sent, time.time_ns()),
                                    *clouds[sent % len(frames)])
            sent += 1
            time.sleep(1 / 30)
        publishing_s = time.monotonic() - started
        publisher.publish_end(sent, sent - 1, "test")
        deadline = time.monotonic() + 20
        while not ends and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        publisher_session.close()
        listener.close()
        hostile.kill()
        hostile.wait()
    # with BLOCK everywhere, puts waited on the never-read link, up to 5 s at a time
    gaps = np.diff([started, *arrivals])
    assert gaps.max() < 3.0, f"the other subscriber waited {gaps.max():.1f} s for a cloud"
    assert len(arrivals) >= 0.5 * sent, (len(arrivals), sent, publishing_s)
    assert ends and ends[0].frames_sent == sent  # what must arrive arrived
