"""Image files read within bounds: only regular files (a FIFO or device would block or never
end), at most `MAX_IMAGE_FILE_PIXELS` (a PNG's size is read from its header before anything is
decoded), decoding failures turned into a `RecordingError` naming the file; and depth images
refused unless they hold integer units (`depth_units`)."""

from __future__ import annotations

import stat
import struct
from pathlib import Path

import numpy as np

from gngdt.io.errors import RecordingError
from gngdt.io.mcap.limits import ReadLimits

__all__ = ["MAX_IMAGE_FILE_PIXELS", "check_depth_dtype", "is_regular_file", "read_image"]

#: largest image read from a file (width x height), as capture's limit for recordings
MAX_IMAGE_FILE_PIXELS = ReadLimits.max_frame_pixels
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def is_regular_file(path: Path) -> bool:
    """Whether ``path`` is a regular file (symbolic links followed); False for folders, FIFOs,
    sockets, devices and what cannot be examined."""
    try:
        return stat.S_ISREG(path.stat().st_mode)
    except OSError:
        return False


def png_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from a PNG's header, or None for another format."""
    with open(path, "rb") as file:
        header = file.read(24)
    if len(header) < 24 or not header.startswith(_PNG_SIGNATURE) or header[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", header[16:24])
    return width, height


def _check_pixels(path: Path, index: int | None, width: int, height: int) -> None:
    if width * height > MAX_IMAGE_FILE_PIXELS:
        raise RecordingError(path, index, f"image of {width}x{height} pixels, more than the "
                             f"{MAX_IMAGE_FILE_PIXELS:,} read (4096x2160)")


def read_image(path: Path, index: int | None, flags: int, what: str) -> np.ndarray:
    """The decoded image (OpenCV's layout) of a regular file of at most
    `MAX_IMAGE_FILE_PIXELS`; ``what`` ("colour image", "depth image") names it in errors."""
    import cv2

    path = Path(path)
    if not is_regular_file(path):
        raise RecordingError(path, index, f"cannot read {what}: not a regular file")
    try:
        size = png_size(path)
        if size is not None:
            _check_pixels(path, index, *size)
        image = cv2.imread(str(path), flags)
    except (OSError, cv2.error) as error:
        reason = str(error).strip().splitlines()[-1] if str(error).strip() else type(error)
        raise RecordingError(path, index, f"cannot read {what}: {reason}") from error
    if image is None:
        raise RecordingError(path, index, f"cannot read {what}")
    _check_pixels(path, index, image.shape[1], image.shape[0])
    return image


def check_depth_dtype(depth: np.ndarray, path: Path, index: int | None) -> None:
    """A depth image must be one channel of integer units (uint16: depth_scale units per
    metre); float depth (metres, usually) is refused with the way to convert it."""
    if depth.ndim != 2:
        raise RecordingError(path, index, f"depth must be single-channel, got shape "
                             f"{depth.shape}")
    if depth.dtype.kind == "f":
        raise RecordingError(
            path, index, f"depth is {depth.dtype} (floating point, usually metres); gngdt reads "
            "depth as uint16 in depth_scale units per metre: convert it, e.g. "
            "np.round(depth_m * 1000).astype(np.uint16) saved as a 16-bit PNG, with "
            "depth_scale 1000")
    if depth.dtype != np.uint16:
        raise RecordingError(path, index, f"depth must be uint16, got {depth.dtype}")
