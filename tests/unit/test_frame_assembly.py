"""Pairing colour and depth by stamp (`gngdt.io.mcap.frame_assembly`): what stays held."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gngdt.core.sensor.geometry import CameraIntrinsics
from gngdt.io.mcap.frame_assembly import DecodedImage, FrameAssembler

CAMERA = CameraIntrinsics(8, 6, 10.0, 10.0, 4.0, 3.0)
PERIOD_NS = 100_000_000


def image(role: str, index: int) -> DecodedImage:
    shape = (6, 8, 3) if role == "color" else (6, 8)
    dtype = np.uint8 if role == "color" else np.uint16
    return DecodedImage(index * PERIOD_NS, np.full(shape, index, dtype))


def test_images_that_can_no_longer_pair_are_not_held() -> None:
    """A live camera whose images are dropped here and there (a flooded bridge drops the oldest
    samples): an image whose partner was lost is let go once a later pair is made, of either
    role, instead of being held until the held-bytes limit."""
    assembler = FrameAssembler(Path("live"), CAMERA, max_skew_ns=8_000_000)
    frames = []
    held_at_most = image("color", 0).pixels.nbytes + image("depth", 0).pixels.nbytes
    for index in range(40):
        roles = ("color", "depth")
        if index % 3 == 1:  # its colour lost
            roles = ("depth",)
        elif index % 3 == 2:  # its depth lost
            roles = ("color",)
        for role in roles:
            frames += assembler.add_image(role, image(role, index))
        # at most one image of each role waits for its partner
        assert assembler.held_bytes() <= held_at_most
    assert [frame.timestamp_ns for frame in frames] == [i * PERIOD_NS for i in range(0, 40, 3)]
    assert all(int(frame.depth[0, 0]) == frame.timestamp_ns // PERIOD_NS for frame in frames)
