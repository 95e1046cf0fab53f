"""The logger under odd or hostile input: cameras it must wait for, cameras it must not grow
for, queues bounded in bytes, topologies bounded by what a learner can send, a bounded .rrd."""

from __future__ import annotations

import time

import pytest
from helpers.pipeline import ImageFlood
from helpers.processes import FILE_SIZE_LIMITED, log_text, wait_for

from gngdt.schemas.wire import FrameStamp


# ---------------------------------------------------------------------------- the inbox
@pytest.mark.timeout(60)
def test_the_inbox_of_a_busy_logger_is_bounded_in_bytes(router_endpoint: str) -> None:
    import zenoh

    from gngdt.services.logger.inbox import Inbox
    from gngdt.services.plumbing.session import client_config, open_config

    inbox = Inbox(max_bytes=5_000_000)  # nothing takes from it: a logger busy elsewhere
    session = open_config(client_config([router_endpoint]))
    session.declare_subscriber("gngdt/**", inbox.put)
    block = zenoh.CongestionControl.BLOCK
    stamp = FrameStamp(1, time.time_ns()).to_attachment()
    try:
        for _ in range(40):  # 1 MB topologies: within their stream's limit, 8x the budget
            session.put("gngdt/camera/topology", b"\x00" * 1_000_000, attachment=stamp,
                        congestion_control=block)
        for _ in range(20):  # 2 MB calibrations: no calibration is this large
            session.put("gngdt/camera/calibration", b"\x00" * 2_000_000, attachment=stamp,
                        congestion_control=block)
        session.put("gngdt/camera/eos", b"end", attachment=stamp, congestion_control=block)
        wait_for(lambda: inbox.oversized == 20 and inbox.dropped >= 35 and inbox.arrived.is_set()
                 and inbox.dropped + 5 >= 40, 30, "every sample to reach the inbox")
    finally:
        session.close()
    taken = inbox.take()
    assert [key for key, _, _ in taken][-1] == "gngdt/camera/eos"  # never evicted
    assert sum(len(payload) for _, payload, _ in taken[:-1]) <= 5_000_000
    assert inbox.dropped + len(taken) - 1 == 40


# ---------------------------------------------------------------------------- the .rrd


@pytest.mark.timeout(120)
def test_the_rrd_stops_at_its_cap_complete_and_the_logger_goes_on(
    router_endpoint: str, spawn, tmp_path
) -> None:
    from rerun.chunk import RrdReader

    rrd_path = tmp_path / "capped.rrd"
    # --keep-everything: every image raw, so that the flood's volume reaches the file
    logger = spawn("log", "--save", str(rrd_path), "--max-rrd-mb", "1", "--eos-drain", "1",
                   "--keep-everything", "--zenoh-connect", router_endpoint)
    wait_for(lambda: "logging to" in log_text(logger), 60, "the logger")
    flood = ImageFlood(router_endpoint)
    flood.run(seconds=1.0)
    wait_for(lambda: "stopped writing" in log_text(logger), 30, "the cap")
    flood.run(seconds=3.0)  # still served after the cap: received, not written
    flood.end()
    assert logger.wait(30) == 0, log_text(logger)
    assert "it reached" in log_text(logger) and "--max-rrd-mb 1" in log_text(logger)
    # the size is checked after every message, and rerun writes a chunk per 2 MiB of an
    # entity's images: ~1 s of this flood (4.6 MB) past the cap at most, of the ~18 MB sent
    assert rrd_path.stat().st_size < 1_000_000 + 7_000_000
    chunks = list(RrdReader(rrd_path).stream().collect().stream())  # complete, with a footer
    assert any(chunk.entity_path == "/world/camera/image/rgb" for chunk in chunks)


@pytest.mark.timeout(120)
def test_a_logger_whose_disk_fills_up_says_so_and_keeps_serving(
    router_endpoint: str, tmp_path
) -> None:
    import subprocess
    import sys
    from pathlib import Path

    rrd_path = tmp_path / "full.rrd"
    log_path = tmp_path / "logger.log"
    with open(log_path, "wb") as output:
        logger = subprocess.Popen(
            [sys.executable, "-c", FILE_SIZE_LIMITED, "log", "--save", str(rrd_path),
             "--eos-drain", "1", "--keep-everything", "--zenoh-connect", router_endpoint],
            cwd=Path(__file__).resolve().parents[2], stdout=output, stderr=output,
            start_new_session=True)
    try:
        wait_for(lambda: "logging to" in log_path.read_text(), 60, "the logger")
        flood = ImageFlood(router_endpoint)
        flood.run(seconds=2.0)  # ~10 MB for a file that cannot pass 3 MB
        wait_for(lambda: "stopped writing" in log_path.read_text(), 60, "the failed write")
        flood.run(seconds=0.5)
        flood.end()  # it still hears the end of stream, and stops by itself
        assert logger.wait(60) == 0, log_path.read_text()
    finally:
        if logger.poll() is None:
            logger.kill()
    text = log_path.read_text()
    assert "writing it failed" in text and "is the disk full?" in text
    assert "Traceback" not in text


