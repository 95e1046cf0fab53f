"""RealSense in the tests: pyrealsense2 must be there in CI (on the platforms it has wheels
for), and elsewhere its absence is a skip naming what is missing. The tests make their own
recordings with the SDK's recorder (`gngdt.io.synth.realsense`)."""

from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

import pytest

from gngdt.io.realsense.sdk import availability

#: the bundled RealSense bags (tests/data/realsense)
DATA = Path(__file__).resolve().parents[1] / "data" / "realsense"
#: pyrealsense2 2.59 publishes wheels for these only
WHEEL_PLATFORM = (sys.platform == "linux" and platform.machine() == "x86_64") or (
    sys.platform == "win32" and platform.machine() == "AMD64")


def require_pyrealsense() -> None:
    """Skip the calling test module when pyrealsense2 cannot be imported, with the reason (what
    to install); in CI on a platform with wheels, fail instead: CI must run these tests."""
    reason = availability()
    if reason is None:
        return
    if os.environ.get("CI") and WHEEL_PLATFORM:
        pytest.fail(f"CI must run the RealSense tests, but {reason}", pytrace=False)
    pytest.skip(reason, allow_module_level=True)
