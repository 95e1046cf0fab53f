"""Environment settings out of range (issue 38): read once at the command line's edge with range
checks, a wrong value named in a warning and ignored, never a crash deep in a service (before,
``GNGDT_SHM_POOL_MB=inf`` or ``1e308`` killed capture with OverflowError when it declared its
publishers, and ``GNGDT_PARENT_PID=abc`` every command with ValueError)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("name", "value"), [
    ("GNGDT_SHM_POOL_MB", "inf"), ("GNGDT_SHM_POOL_MB", "1e308"),
    ("GNGDT_SHM_POOL_MB", "nan"), ("GNGDT_PARENT_PID", "abc"),
])
def test_capture_runs_with_a_setting_out_of_range_and_names_it(
        router_endpoint: str, one_frame_recording: Path, tmp_path: Path,
        name: str, value: str) -> None:
    log = tmp_path / "capture.log"
    with open(log, "wb") as output:
        capture = subprocess.Popen(
            [sys.executable, "-m", "gngdt.services.cli", "capture", str(one_frame_recording),
             "--fast", "--zenoh-connect", router_endpoint, "--wait-subscribers", "0",
             "--wait-learner", "0"],  # no learner here: not a minute's wait for one
            cwd=REPO_ROOT, stdout=output, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True, env={**os.environ, name: value})
    try:
        code = capture.wait(90)
    finally:
        if capture.poll() is None:
            os.killpg(capture.pid, signal.SIGKILL)
            capture.wait()
    text = log.read_text()
    assert code == 0, text[-3000:]
    assert f"{name}={value!r}" in text and "Traceback" not in text
    assert "sent 1 frames" in text
