"""Errors raised while reading or importing recordings."""

from __future__ import annotations

from pathlib import Path


class RecordingError(Exception):
    """A recording (or an image folder) cannot be read, at a known place.

    ``path``: the file or folder; ``frame``: index of the frame being assembled (None when the
    problem is not tied to a frame); ``reason``: what is wrong.
    ``str()`` reads like
    ``"recordings/x.mcap: frame 12: depth 320x240 does not match colour 640x480"``.
    """

    def __init__(self, path: str | Path, frame: int | None, reason: str) -> None:
        self.path = str(path)
        self.frame = frame
        self.reason = reason
        super().__init__(str(self))

    def __str__(self) -> str:
        where = f"{self.path}: frame {self.frame}" if self.frame is not None else self.path
        return f"{where}: {self.reason}"
