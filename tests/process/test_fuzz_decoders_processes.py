"""Hostile payloads on every topic: the services' own per-sample decode paths never raise
anything but ``ValueError`` (counted, skipped), and size limits hold before any allocation.

Property-based (hypothesis) on random bytes and on structurally valid messages with hostile
fields, plus one process-level flood of a running learner and logger over a real zenoh router.
"""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.processes import wait_for

from gngdt.schemas.clouds import cloud_to_msg
from gngdt.schemas.status import encode_stream_end
from gngdt.schemas.wire import FrameStamp

#: every stream the logger subscribes to (``gngdt/<cam>/<stream>``)
STREAMS = ("color", "depth", "calibration", "points", "topology", "objects", "learner/status",
           "eos")
GOOD_ATTACHMENT = FrameStamp(1, time.time_ns()).to_attachment()  # a day of validity


# ------------------------------------------------------------ flooding the running services

@pytest.mark.timeout(150)
def test_flooded_learner_and_logger_count_garbage_and_keep_working(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    import zenoh
    from rerun.chunk import RrdReader

    from gngdt.schemas.status import decode_status
    from gngdt.services.plumbing.session import client_config, open_config

    rrd_path = tmp_path / "flood.rrd"
    connect = ("--zenoh-connect", router_endpoint)
    learner = spawn("learn", "--samples-per-frame", "500", *connect)
    # --keep-everything: every sample is decoded (by default the logger skips, undecoded, the
    # images and clouds it does not log)
    logger = spawn("log", "--save", str(rrd_path), "--keep-running", "--keep-everything",
                   *connect)
    session = open_config(client_config([router_endpoint]))
    statuses: list = []
    session.declare_subscriber("gngdt/camera/learner/status",
                               lambda sample: statuses.append(decode_status(
                                   sample.payload.to_bytes())))
    try:
        liveliness = session.liveliness()
        wait_for(lambda: len(list(liveliness.get("gngdt/**/alive/**", timeout=1))) >= 2,
              60, "learner and logger liveliness tokens")
        block = zenoh.CongestionControl.BLOCK
        rng = np.random.default_rng(7)
        garbage = 0
        for index in range(60):
            stream = STREAMS[index % len(STREAMS)]
            # non-empty bytes that are not a valid message of any kind: a varint-length field
            # running past the end, so protobuf refuses it on every topic
            payload = b"\x0a\xff\xff\x03" + rng.bytes(int(rng.integers(0, 200)))
            attachment = GOOD_ATTACHMENT if index % 2 else rng.bytes(5)
            session.put(f"gngdt/camera/{stream}", payload, attachment=attachment,
                        congestion_control=block)
            garbage += 1
            time.sleep(0.01)
        time.sleep(1.0)
        assert learner.poll() is None and logger.poll() is None
        # then a good frame: still learned and logged
        positions = rng.random((3000, 3), dtype=np.float32)
        cloud = cloud_to_msg(positions, rng.integers(0, 256, (3000, 3), dtype=np.uint8),
                             timestamp_ns=time.time_ns())
        session.put("gngdt/camera/points", cloud.SerializeToString(),
                    attachment=FrameStamp(5, time.time_ns()).to_attachment(),
                    congestion_control=block)
        wait_for(lambda: any(status.frame_sequence == 5 for status in statuses), 60,
              "the good frame's status")
        good = next(status for status in statuses if status.frame_sequence == 5)
        # the points ring channel keeps only the newest sample, so not every garbage cloud is
        # seen; the eos ones always are (a callback)
        eos_garbage = sum(1 for index in range(60) if STREAMS[index % len(STREAMS)] == "eos")
        assert good.malformed_messages >= eos_garbage
        assert good.frames_used == 1 and good.nodes > 2
        end = encode_stream_end(timestamp_ns=1, frames_sent=1, last_frame_sequence=5)
        session.put("gngdt/camera/eos", end.SerializeToString(),
                    attachment=FrameStamp(5, time.time_ns()).to_attachment(),
                    congestion_control=block)
        time.sleep(1.0)
    finally:
        session.close()
    for process in (learner, logger):
        process.send_signal(signal.SIGINT)
        assert process.wait(30) == 0, Path(process.log_path).read_text()
    logged = Path(logger.log_path).read_text()
    malformed = int(re.search(r"logger done: (\d+) malformed", logged).group(1))
    # every garbage message on a queued stream is counted; on a latest-only stream (images,
    # clouds, objects) a newer one may supersede it before it is decoded, but not all are
    from gngdt.services.logger.inbox import LATEST_ONLY_STREAMS

    queued = sum(1 for index in range(60)
                 if STREAMS[index % len(STREAMS)] not in LATEST_ONLY_STREAMS)
    assert queued < malformed <= garbage
    store = RrdReader(rrd_path).stream().collect()
    entities = {chunk.entity_path for chunk in store.stream()}
    assert {"/world/gng/nodes", "/metrics/nodes"} <= entities


