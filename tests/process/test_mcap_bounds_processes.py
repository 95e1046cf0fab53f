"""A logger whose disk fills up while it records an MCAP (issue 24.3): it stops writing, says
why, leaves a file the mcap package reads, and exits 0."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from helpers.pipeline import ImageFlood
from helpers.processes import FILE_SIZE_LIMITED, wait_for

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(120)
def test_a_full_disk_leaves_a_readable_mcap_and_the_logger_exits_0(
        router_endpoint: str, tmp_path: Path) -> None:
    from mcap.reader import make_reader

    mcap_path = tmp_path / "full.mcap"
    log_path = tmp_path / "logger.log"
    with open(log_path, "wb") as output:  # every file of the logger stops at 3 MB
        logger = subprocess.Popen(
            [sys.executable, "-c", FILE_SIZE_LIMITED, "log", "--save", str(tmp_path / "x.rrd"),
             "--image-every", "1000", "--mcap", str(mcap_path), "--eos-drain", "1",
             "--zenoh-connect", router_endpoint],
            cwd=REPO_ROOT, stdout=output, stderr=output, start_new_session=True)
    try:
        wait_for(lambda: "recording to" in log_path.read_text(), 60, "the logger")
        flood = ImageFlood(router_endpoint)
        flood.run(seconds=2.0)  # ~9 MB of images for a file that cannot pass 3 MB
        wait_for(lambda: "stopped writing" in log_path.read_text(), 60, "the failed write")
        flood.run(seconds=0.5)
        flood.end()
        assert logger.wait(60) == 0, log_path.read_text()
    finally:
        if logger.poll() is None:
            logger.kill()
    text = log_path.read_text()
    assert "writing it failed" in text and "is the disk full?" in text
    assert "Traceback" not in text
    with open(mcap_path, "rb") as file:
        topics = [channel.topic for _, channel, _ in make_reader(file).iter_messages()]
    assert len(topics) >= 5 and set(topics) == {"/camera/color"}
    assert mcap_path.stat().st_size <= 3_000_000


@pytest.mark.timeout(240)
def test_a_run_whose_mcap_fills_its_disk_says_so_and_exits_4(tabletop_recording: Path,
                                                              tmp_path: Path) -> None:
    from mcap.reader import make_reader

    mcap_path = tmp_path / "run.mcap"
    completed = subprocess.run(  # every file of the run stops at 3 MB; its MCAP needs ~4 MB
        [sys.executable, "-c", FILE_SIZE_LIMITED, "run", str(tabletop_recording), "--fast",
         "--max-points", "0", "--save", str(tmp_path / "run.rrd"), "--mcap", str(mcap_path)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=200)
    assert completed.returncode == 4, completed.stdout + completed.stderr  # issue 35.6
    assert "frames sent:        8 of 8" in completed.stdout
    assert f"WARNING: recording to {mcap_path} stopped early: writing it failed" in \
        completed.stdout
    with open(mcap_path, "rb") as file:
        topics = [channel.topic for _, channel, _ in make_reader(file).iter_messages()]
    assert topics and 1_000_000 < mcap_path.stat().st_size <= 3_000_000  # cut at the limit
