"""RealSense recordings on disk, checked before the SDK opens them.

Since SDK 2.58 the recorder writes a rosbag2 SQLite file (``.db3``, one file, CDR messages):
per stream ``/device_0/sensor_N/{Depth,Color}_0/image/data`` (lossless PNG) and
``.../image/metadata`` (``"Frame number=12;...;depth_units=0.001000"``), plus camera info,
options and ``/tf_static``. Older SDKs wrote a ROS 1 ``.bag``, which 2.59 still reads.

The SDK reports neither damage nor the end of a file well: a truncated ``.db3`` fails deep in
SQLite, an undecodable frame ends playback silently, and on one corrupt ``.bag`` its ROS 1
reader looped forever holding the GIL. So a ``.db3`` is checked with sqlite3 first
(`inspect_db3`: integrity, image counts, first frame numbers) and a ``.bag`` is converted to a
``.db3`` in a child process with a time limit (`convert_legacy_bag`), which also plays every
frame of it (played directly, a legacy ``.bag`` loses its first frameset).
"""

from __future__ import annotations

import re
import sqlite3
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from gngdt.io.errors import RecordingError

#: the first bytes of a SQLite file (a ``.db3``) and of a ROS 1 bag (a legacy ``.bag``)
SQLITE_MAGIC = b"SQLite format 3\x00"
ROSBAG_MAGIC = b"#ROSBAG V2.0"
DEPTH_IMAGES = "/device_%/sensor_%/Depth_%/image/data%"
COLOR_IMAGES = "/device_%/sensor_%/Color_%/image/data%"
DEPTH_METADATA = "/device_%/sensor_%/Depth_%/image/metadata"
COLOR_METADATA = "/device_%/sensor_%/Color_%/image/metadata"
_FRAME_NUMBER = re.compile(rb"Frame number=(\d+)")


@dataclass(frozen=True)
class RecordingInfo:
    """What a ``.db3`` recording holds: image counts per stream and each one's first frame
    number (None when its metadata does not say)."""

    depth_frames: int
    color_frames: int
    first_depth_number: int | None = None
    first_color_number: int | None = None


def file_kind(path: Path) -> str:
    """``"db3"``, ``"bag"`` or ``""`` (neither), by the file's first bytes."""
    with open(path, "rb") as stream:
        head = stream.read(len(SQLITE_MAGIC))
    if head == SQLITE_MAGIC:
        return "db3"
    return "bag" if head.startswith(ROSBAG_MAGIC) else ""


def inspect_db3(path: Path) -> RecordingInfo:
    """Check a ``.db3`` recording with sqlite3 (read-only) and count its images; RecordingError
    when it is no SQLite file, fails ``PRAGMA quick_check`` or lacks depth or colour images."""
    try:
        connection = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    except sqlite3.Error as error:
        raise RecordingError(path, None, f"cannot open as a .db3 recording: {error}") from error
    try:
        check = connection.execute("PRAGMA quick_check").fetchall()
        if check != [("ok",)]:
            detail = "; ".join(str(row[0]) for row in check[:3])
            raise RecordingError(path, None, f"damaged recording (sqlite quick_check: {detail})")
        _check_blobs(path, connection)
        info = RecordingInfo(_count(connection, DEPTH_IMAGES), _count(connection, COLOR_IMAGES),
                             _first_number(connection, DEPTH_METADATA),
                             _first_number(connection, COLOR_METADATA))
    except sqlite3.DatabaseError as error:
        raise RecordingError(path, None, f"damaged, or not a RealSense recording: {error}"
                             ) from error
    finally:
        connection.close()
    if info.depth_frames == 0 or info.color_frames == 0:
        raise RecordingError(
            path, None, f"not a RealSense recording with depth and colour: it has "
            f"{info.depth_frames} depth and {info.color_frames} colour images on the SDK's "
            "topics (/device_0/sensor_N/...); a ROS 2 bag in .db3 reads once converted to MCAP "
            "(ros2 bag convert)")
    return info


def _check_blobs(path: Path, connection: sqlite3.Connection) -> None:
    """RecordingError unless every message is a BLOB, as rosbag2 and the SDK write them (a
    message stored as TEXT, a number or NULL is damage or a forgery; the SDK's reader and this
    module would choke on it)."""
    row = connection.execute(
        "SELECT t.name, typeof(m.data), COUNT(*) FROM messages m JOIN topics t "
        "ON t.id = m.topic_id WHERE typeof(m.data) != 'blob' GROUP BY t.name, typeof(m.data) "
        "ORDER BY COUNT(*) DESC LIMIT 1").fetchone()
    if row is not None:
        topic, kind, count = row
        raise RecordingError(path, None, f"damaged, or not written by the RealSense SDK: "
                             f"{count} messages of {topic} are stored as {kind.upper()}, not "
                             "as BLOB")


def _count(connection: sqlite3.Connection, topic_like: str) -> int:
    row = connection.execute(
        "SELECT COUNT(*) FROM messages m JOIN topics t ON t.id = m.topic_id WHERE t.name LIKE ?",
        (topic_like,)).fetchone()
    return int(row[0])


def _first_number(connection: sqlite3.Connection, topic_like: str) -> int | None:
    row = connection.execute(
        "SELECT m.data FROM messages m JOIN topics t ON t.id = m.topic_id WHERE t.name LIKE ? "
        "ORDER BY m.timestamp, m.id LIMIT 1", (topic_like,)).fetchone()
    match = _FRAME_NUMBER.search(row[0]) if row else None
    return int(match.group(1)) if match else None


_CONVERT = (
    "import sys\n"
    "import pyrealsense2 as rs\n"
    "try:\n"
    "    rs.context().convert_bag_to_db3(sys.argv[1], sys.argv[2])\n"
    "except RuntimeError as error:\n"
    "    sys.exit(str(error))\n"
)


def default_convert_timeout(bag: Path) -> float:
    """Time allowed to convert ``bag``: 30 s + 1 s per 5 MB."""
    return 30.0 + bag.stat().st_size / 5e6


def convert_legacy_bag(bag: Path, out_db3: Path, timeout_s: float | None = None) -> None:
    """Convert a legacy ROS 1 ``.bag`` to ``.db3`` with the SDK's converter, in a child process
    limited to ``timeout_s`` (default `default_convert_timeout`). RecordingError naming the file
    when the SDK cannot convert it or does not finish (a partial output is removed)."""
    timeout_s = default_convert_timeout(bag) if timeout_s is None else timeout_s
    try:
        run = subprocess.run([sys.executable, "-c", _CONVERT, str(bag), str(out_db3)],
                             capture_output=True, text=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired as error:
        out_db3.unlink(missing_ok=True)
        raise RecordingError(bag, None, f"the SDK did not finish reading this legacy .bag in "
                             f"{timeout_s:.0f} s (a damaged .bag can make it loop forever)"
                             ) from error
    if run.returncode != 0:
        out_db3.unlink(missing_ok=True)
        lines = (run.stderr or "").strip().splitlines()
        detail = lines[-1] if lines else f"exit status {run.returncode}"
        raise RecordingError(bag, None, f"unreadable legacy .bag recording: {detail}")
