"""Recordings that cost time or memory out of proportion: a jump in the stamps, oversized frames
and chunks, frames that never get a calibration. The capture bounds each and says so."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import pytest


def _log(process) -> str:
    return Path(process.log_path).read_text(errors="replace")


def _frames(count: int, width: int = 64, height: int = 48):
    from services.recording.synth import render_scene

    return list(render_scene("data2", count, width=width, height=height))


@pytest.mark.timeout(90)
def test_a_jump_in_the_stamps_is_shortened_and_said(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    from services.recording.writer import RecordingWriter

    path = tmp_path / "jump.mcap"
    first, second = _frames(2)
    second = dataclasses.replace(second, timestamp_ns=first.timestamp_ns + 10**6 * 10**9)
    with RecordingWriter(path) as writer:
        writer.write_frame(first)
        writer.write_frame(second)  # stamped 11.6 days later
    started = time.monotonic()
    capture = spawn("capture", str(path), "--rate", "1", "--max-gap", "0.5",
                    "--wait-subscribers", "0", "--zenoh-connect", router_endpoint)
    assert capture.wait(60) == 0, _log(capture)
    assert time.monotonic() - started < 50
    assert "is stamped 1e+06 s after the previous one; waiting 0.5 s instead" in _log(capture)
    assert "sent 2 frames" in _log(capture)


def test_the_replay_clock_keeps_the_recorded_spacing_below_the_cap() -> None:
    import threading

    from services.capture import ReplayClock

    clock = ReplayClock(rate=2.0, max_gap_s=0.3)
    stop = threading.Event()
    started = time.monotonic()
    for stamp_s in (0.0, 0.2, 0.4, 100.0, 100.2):  # 0.1 s apart at 2x, one gap of 49.8 s
        clock.wait_for(round(stamp_s * 1e9), stop)
    elapsed = time.monotonic() - started
    assert 0.55 <= elapsed < 5.0  # 0.1 + 0.1 + 0.3 (capped) + 0.1
