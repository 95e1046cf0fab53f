"""Recordings open in rerun as they are: `rerun mcap convert` keeps the images and calibration."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gngdt.io.frame import CameraIntrinsics, Frame
from gngdt.io.mcap.writer import RecordingWriter


def _rerun_executable() -> str:
    beside_python = Path(sys.executable).with_name("rerun")
    found = str(beside_python) if beside_python.exists() else shutil.which("rerun")
    if found is None:
        pytest.fail("the rerun CLI (shipped with rerun-sdk) is not installed")
    return found


@pytest.mark.parametrize("color_format", ["raw", "jpeg"])
def test_rerun_converts_a_recording(tmp_path: Path, color_format: str) -> None:
    from rerun.chunk import RrdReader

    rng = np.random.default_rng(0)
    intrinsics = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    recording = tmp_path / "in.mcap"
    with RecordingWriter(recording, color_format=color_format) as writer:
        for index in range(3):
            writer.write_frame(
                Frame(
                    index=index,
                    timestamp_ns=1_700_000_000_000_000_000 + index * 33_333_333,
                    color=rng.integers(0, 256, (48, 64, 3), dtype=np.uint8),
                    depth=rng.integers(1, 5000, (48, 64), dtype=np.uint16),
                    intrinsics=intrinsics,
                    labels=np.ones((48, 64), np.uint16),
                )
            )
    converted = tmp_path / "out.rrd"
    environment = os.environ | {"XDG_CONFIG_HOME": str(tmp_path / "config")}
    result = subprocess.run(
        [_rerun_executable(), "mcap", "convert", str(recording), "-o", str(converted)],
        capture_output=True,
        text=True,
        env=environment,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    rows: dict[str, int] = {}
    store = RrdReader(converted).stream().collect()
    for chunk in store.stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    for topic in ("/camera/color", "/camera/depth", "/camera/calibration", "/camera/labels"):
        assert rows.get(topic, 0) >= 3, f"{topic} missing from the .rrd; entities: {sorted(rows)}"
