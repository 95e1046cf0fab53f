"""The logger under odd or hostile input: cameras it must wait for, cameras it must not grow
for, queues bounded in bytes, topologies bounded by what a learner can send, a bounded .rrd."""

from __future__ import annotations

import time

import pytest
from processes import wait_for

from gngdt.schemas.status import encode_stream_end
from gngdt.schemas.wire import ENCODING_RAW_IMAGE, FrameStamp


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
class ImageFlood:
    """A camera publishing 320x240 colour images at ~20 Hz, then an end of stream."""

    def __init__(self, endpoint: str) -> None:
        from gngdt.services.plumbing.session import client_config, open_config

        self.session = open_config(client_config([endpoint]))
        self.sent = 0

    def run(self, seconds: float) -> None:
        import numpy as np
        import zenoh

        from gngdt.schemas.images import image_to_raw

        rng = np.random.default_rng(0)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            image = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)  # incompressible
            now = time.time_ns()
            self.session.put("gngdt/camera/color", image_to_raw(image, timestamp_ns=now)
                             .SerializeToString(), attachment=FrameStamp(self.sent, now)
                             .to_attachment(), encoding=ENCODING_RAW_IMAGE,
                             congestion_control=zenoh.CongestionControl.BLOCK)
            self.sent += 1
            time.sleep(0.05)

    def end(self) -> None:
        import zenoh

        _eos_put(self.session, self.sent)
        self.session.close()
        del zenoh


def _eos_put(session, frames: int) -> None:
    import zenoh

    message = encode_stream_end(timestamp_ns=time.time_ns(), frames_sent=frames,
                                last_frame_sequence=max(frames - 1, 0))
    session.put("gngdt/camera/eos", message.SerializeToString(),
                attachment=FrameStamp(max(frames - 1, 0), time.time_ns()).to_attachment(),
                congestion_control=zenoh.CongestionControl.BLOCK)


@pytest.mark.timeout(120)
def test_the_rrd_stops_at_its_cap_complete_and_the_logger_goes_on(
    router_endpoint: str, spawn, tmp_path
) -> None:
    from processes import log_text
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


#: runs gngdt with writes limited to a few megabytes a file, as a full disk would stop them
FILE_SIZE_LIMITED = (
    "import os, resource, signal, sys\n"
    "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a kill\n"
    "resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))\n"
    "os.execv(sys.executable, [sys.executable, '-m', 'gngdt.services.cli', *sys.argv[1:]])\n"
)


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


