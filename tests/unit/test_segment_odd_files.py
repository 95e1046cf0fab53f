"""`gngdt segment` on odd folders (issue 24.5): an image beyond its pixel limit refused from its
header, a FIFO skipped (it must not hang), NaN camera parameters named, and tiny frames given
a node budget (and steps) their pixels can fill."""

from __future__ import annotations

import json
import logging
import os
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from gngdt.services.cli import main as gngdt


def tiny_folder(folder: Path, frames: int = 2, size: tuple[int, int] = (8, 8)) -> Path:
    """A redwood folder of flat frames at 1 m, and its camera.json."""
    height, width = size
    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    rng = np.random.default_rng(0)
    for index in range(frames):
        name = f"{index:06d}.png"
        cv2.imwrite(str(folder / "color" / name), rng.integers(0, 256, (height, width, 3),
                                                               dtype=np.uint8))
        cv2.imwrite(str(folder / "depth" / name), np.full((height, width), 1000, np.uint16))
    (folder / "camera.json").write_text(json.dumps({
        "fx": 10.0, "fy": 10.0, "cx": width / 2, "cy": height / 2, "depth_scale": 1000.0}))
    return folder


def png_claiming(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` x ``height`` 8-bit RGB pixels, with a few bytes of
    data (OpenCV would allocate the whole image before finding out)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + chunk(b"IEND", b""))


@pytest.mark.parametrize("size", [(100_000, 100_000), (4097, 2161)])
def test_an_image_beyond_the_pixel_limit_is_refused_from_its_header(
        tmp_path: Path, caplog, size: tuple[int, int]) -> None:
    folder = tiny_folder(tmp_path / "frames")
    (folder / "color" / "000001.png").write_bytes(png_claiming(*size))
    with caplog.at_level(logging.ERROR):
        assert gngdt(["segment", str(folder), "--out", str(tmp_path / "out")]) == 2
    assert f"image of {size[0]}x{size[1]} pixels, more than" in caplog.text
    assert "000001.png" in caplog.text and not (tmp_path / "out").exists()


@pytest.mark.timeout(120)
def test_a_fifo_among_the_images_is_skipped_not_read(tmp_path: Path) -> None:
    folder = tiny_folder(tmp_path / "frames")
    for kind in ("color", "depth"):
        os.mkfifo(folder / kind / "000002.png")  # opening it to read would block for ever
    out = tmp_path / "out"
    assert gngdt(["segment", str(folder), "--out", str(out)]) == 0
    assert sorted(path.name for path in out.iterdir()) == ["000000.png", "000001.png",
                                                           "summary.json"]


def test_nan_camera_parameters_are_named(tmp_path: Path, caplog) -> None:
    folder = tiny_folder(tmp_path / "frames")
    (folder / "camera.json").write_text('{"fx": NaN, "fy": 10, "cx": 4, "cy": 4, '
                                        '"depth_scale": 1000}')
    with caplog.at_level(logging.ERROR):
        assert gngdt(["segment", str(folder), "--out", str(tmp_path / "out")]) == 2
    assert "camera.json" in caplog.text and "must be finite" in caplog.text


def test_tiny_frames_get_a_node_budget_their_pixels_can_fill(tmp_path: Path) -> None:
    """8x8 frames with the Kinect profile's 4,000 nodes: before, ~2 s a frame for 64 points."""
    folder = tiny_folder(tmp_path / "frames", frames=3)
    out = tmp_path / "out"
    assert gngdt(["segment", str(folder), "--out", str(out), "--independent"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert all(frame["nodes"] <= 64 // 16 for frame in summary["per_frame"])
    later = [frame["milliseconds"]["total"] for frame in summary["per_frame"][1:]]
    assert max(later) < 500  # measured ~10 ms (the first frame pays numba's start)
