"""Recordings that cost time or memory out of proportion: a jump in the stamps, oversized frames
and chunks, frames that never get a calibration. The capture bounds each and says so."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from hostile_recordings import lz4_chunk_hiding_its_size, overlapping_chunks, zstd_bomb


def _log(process) -> str:
    return Path(process.log_path).read_text(errors="replace")


def _frames(count: int, width: int = 64, height: int = 48):
    from gngdt.io.synth.render import render_scene

    return list(render_scene("data2", count, width=width, height=height))


@pytest.mark.timeout(90)
def test_a_jump_in_the_stamps_is_shortened_and_said(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    from gngdt.io.mcap.writer import RecordingWriter

    path = tmp_path / "jump.mcap"
    first, second = _frames(2)
    second = dataclasses.replace(second, timestamp_ns=first.timestamp_ns + 10**6 * 10**9)
    with RecordingWriter(path) as writer:
        writer.write_frame(first)
        writer.write_frame(second)  # stamped 11.6 days later
    started = time.monotonic()
    capture = spawn("capture", str(path), "--rate", "1", "--max-gap", "0.5", "--realtime",
                    "--wait-subscribers", "0", "--zenoh-connect", router_endpoint)
    assert capture.wait(60) == 0, _log(capture)
    assert time.monotonic() - started < 50
    assert "is stamped 1e+06 s after the previous one; waiting 0.5 s instead" in _log(capture)
    assert "sent 2 frames" in _log(capture)


def _capture(router_endpoint: str, path: Path, *options: str) -> tuple[int, str, float]:
    """Run `gngdt capture PATH --fast`: exit status, output, peak RSS in MB."""
    import subprocess
    import sys

    from helpers.processes import peak_rss_mb, with_peak_rss

    completed = subprocess.run(
        with_peak_rss([sys.executable, "-m", "gngdt.services.cli", "capture", str(path), "--fast",
                       "--realtime", "--wait-subscribers", "0", "--zenoh-connect",
                       router_endpoint, *options]),
        cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True, timeout=120)
    output = completed.stdout + completed.stderr
    return completed.returncode, output, peak_rss_mb(output)


def _write_images(path: Path, images: list[tuple[str, object]], calibrated: bool) -> None:
    """An MCAP of raw images (role, array), stamped 33 ms apart, with a calibration for each
    colour image, or (not ``calibrated``) a single one only after the last image: the reader
    holds every frame before it."""
    from mcap_protobuf.writer import Writer

    from gngdt.io.frame import CameraIntrinsics
    from gngdt.schemas.images import image_to_raw, intrinsics_to_calibration

    with open(path, "wb") as file, Writer(file) as writer:
        for index, (role, image) in enumerate(images):
            stamp = 1_000_000_000 + index // 2 * 33_000_000
            if calibrated and role == "color":
                height, width = image.shape[:2]
                intrinsics = CameraIntrinsics(width, height, 500.0, 500.0, width / 2, height / 2)
                writer.write_message("/camera/calibration", intrinsics_to_calibration(
                    intrinsics, timestamp_ns=stamp), log_time=stamp, publish_time=stamp)
            writer.write_message(f"/camera/{role}", image_to_raw(image, timestamp_ns=stamp),
                                 log_time=stamp, publish_time=stamp)
        if not calibrated:
            height, width = images[-1][1].shape[:2]
            late = 2_000_000_000 + len(images) * 33_000_000
            writer.write_message("/camera/calibration", intrinsics_to_calibration(
                CameraIntrinsics(width, height, 500.0, 500.0, width / 2, height / 2),
                timestamp_ns=late), log_time=late, publish_time=late)


@pytest.mark.timeout(120)
def test_one_huge_frame_is_refused_before_it_costs_a_gigabyte(
    router_endpoint: str, tmp_path: Path
) -> None:
    import numpy as np

    path = tmp_path / "huge.mcap"
    _write_images(path, [("color", np.zeros((4000, 4000, 3), np.uint8)),
                         ("depth", np.zeros((4000, 4000), np.uint16))], calibrated=True)
    assert path.stat().st_size < 200_000  # zeros: a few kilobytes for 80 MB of pixels
    code, output, peak_mb = _capture(router_endpoint, path)
    assert code == 2, output
    assert "huge.mcap: frame 0: /camera/color: image 4000x4000 exceeds the limit" in output
    assert "--max-frame-pixels" in output and "Traceback" not in output
    assert peak_mb < 400, f"{peak_mb:.0f} MB"  # was 1,383 MB


@pytest.mark.timeout(120)
def test_frames_that_never_get_a_calibration_are_held_within_a_budget(
    router_endpoint: str, tmp_path: Path
) -> None:
    import numpy as np

    path = tmp_path / "uncalibrated.mcap"
    color, depth = np.zeros((2000, 2000, 3), np.uint8), np.zeros((2000, 2000), np.uint16)
    _write_images(path, [(role, image) for _ in range(64)
                         for role, image in (("color", color), ("depth", depth))],
                  calibrated=False)
    code, output, peak_mb = _capture(router_endpoint, path, "--max-pending-mb", "64")
    assert code == 2, output
    assert "uncalibrated.mcap: frame 0: no calibration channel" in output
    assert "--max-pending-mb" in output
    assert peak_mb < 400, f"{peak_mb:.0f} MB"  # was 1,332 MB


@pytest.fixture
def own_peak_mb(router_endpoint: str) -> float:
    """Capture's own peak RSS in MB (the interpreter, zenoh, MCAP and numba's deprojection
    kernels) replaying the small bundled recording: what a bomb's cost is measured above."""
    recording = Path(__file__).resolve().parents[2] / "recordings" / "tabletop_small.mcap"
    code, output, peak_mb = _capture(router_endpoint, recording)
    assert code == 0, output
    return peak_mb


@pytest.mark.timeout(120)
def test_a_chunk_that_inflates_beyond_the_limit_is_refused_before_decompression(
    router_endpoint: str, tmp_path: Path, own_peak_mb: float
) -> None:
    path = zstd_bomb(tmp_path / "bomb.mcap", 96 * 1024 * 1024)
    assert path.stat().st_size < 100_000
    started = time.monotonic()
    code, output, peak_mb = _capture(router_endpoint, path, "--max-chunk-mb", "64")
    assert code == 2, output
    assert "bomb.mcap: a zstd chunk of" in output and "--max-chunk-mb" in output
    assert time.monotonic() - started < 60
    assert peak_mb - own_peak_mb < 48, f"{peak_mb:.0f} MB, {own_peak_mb:.0f} MB replaying a file"


@pytest.mark.timeout(120)
def test_an_lz4_chunk_that_hides_its_size_is_refused_before_it_is_inflated(
    router_endpoint: str, tmp_path: Path, own_peak_mb: float
) -> None:
    path = lz4_chunk_hiding_its_size(tmp_path / "lz4-bomb.mcap", 256 * 1024 * 1024)
    assert path.stat().st_size < 1_200_000  # 1.1 MB of lz4 for 256 MB of zeros
    code, output, peak_mb = _capture(router_endpoint, path)
    assert code == 2, output
    assert "lz4-bomb.mcap: a lz4 chunk of" in output and "--max-chunk-mb" in output
    assert "Traceback" not in output
    # mcap inflated it whole: 544 MB, 360 MB above a replay
    assert peak_mb - own_peak_mb < 128, f"{peak_mb:.0f} MB, {own_peak_mb:.0f} MB replaying a file"


@pytest.mark.timeout(120)
def test_chunks_that_overlap_in_time_are_inflated_one_at_a_time(
    router_endpoint: str, tmp_path: Path
) -> None:
    # 16 chunks of 40 MB, each starting early and ending late: all overlap in time
    path = overlapping_chunks(tmp_path / "overlap.mcap", 16, 40 * 1024 * 1024)
    assert path.stat().st_size < 100_000
    code, output, peak_mb = _capture(router_endpoint, path)
    assert code == 2, output  # 40 MB of zeros is no image: every message is a bad frame
    assert "overlap.mcap: no color or depth image channel found" in output, output
    assert "Traceback" not in output
    # a merge by log time held all 16 chunks inflated at once (about 640 MB more)
    assert peak_mb < 400, f"{peak_mb:.0f} MB"


