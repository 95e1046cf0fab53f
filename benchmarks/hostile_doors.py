"""Issue 38's attacks on the new doors, for ``bench_hostile.py`` (and the inputs the tests make of
them): calibrations with absurd finite values, a /tf stamp in 2038, RealSense files made odd on
purpose, environment settings out of range, checkpoints and poses beyond the workspace,
Foxglove clients that never read, a ROS 2 image flood, credentials a killed run left behind.
Each is a real command (or a real service under a real client) on small generated input; per
attack, the exit code of every process, the peak RSS of the largest one, whether a traceback
reached the user, and what was learned or kept."""

from __future__ import annotations

import shutil
import sqlite3
import struct
import tempfile
from pathlib import Path

from hostile_trust import GNGDT, Attack, attack, line_with, run

# ----------------------------------------------------------------- RealSense files, made odd


def cdr_string(text: str) -> bytes:
    """A std_msgs/String in CDR: the little-endian header, the length with its NUL, the bytes."""
    data = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data)) + data


def cdr_text(data: bytes) -> str:
    """The text of a std_msgs/String in CDR."""
    (length,) = struct.unpack("<I", data[4:8])
    return data[8:8 + length - 1].decode()


def rewrite_stream_info(path: Path, streams: str, edit) -> Path:
    """Apply ``edit`` (str -> str) to the SDK's stream descriptions (``width=..;height=..;
    fx=..``) of ``streams`` (``Color``, ``Depth``, or ``_`` for both) in a ``.db3``."""
    with sqlite3.connect(path) as connection:
        rows = connection.execute(
            "SELECT m.id, m.data FROM messages m JOIN topics t ON t.id = m.topic_id "
            "WHERE t.name LIKE ?", (f"%{streams}%_0/camera_info",)).fetchall()
        if not rows:
            raise ValueError(f"{path}: no stream description of {streams!r}")
        for row_id, data in rows:
            connection.execute("UPDATE messages SET data = ? WHERE id = ?",
                               (cdr_string(edit(cdr_text(data))), row_id))
    return path


def odd_realsense_recordings(folder: Path, frames: int = 3) -> dict[str, Path]:
    """A small recording the SDK wrote (64x48), and copies made odd: every stream claiming
    65535x65535; the colour one 65535x48000 with a plausible field of view (over any pixel
    limit); the image metadata rows stored as TEXT instead of BLOB. Needs pyrealsense2."""
    from gngdt.io.synth.realsense import write_virtual_recording

    folder.mkdir(parents=True, exist_ok=True)
    base = write_virtual_recording(folder / "base.db3", frames=frames, width=64, height=48).path
    made = {"base": base}

    def copy(name: str) -> Path:
        made[name] = shutil.copy(base, folder / f"{name}.db3")
        return made[name]

    size = "width=64;height=48"
    rewrite_stream_info(copy("huge"), "_", lambda text: text.replace(
        size, "width=65535;height=65535"))
    wide = {size: "width=65535;height=48000", "fx=61.5499992": "fx=60000",
            "fy=61.5750008": "fy=60000", "ppx=31.8624992": "ppx=32767",
            "ppy=24.2374992": "ppy=24000"}

    def widen(text: str) -> str:
        for old, new in wide.items():
            text = text.replace(old, new)
        return text

    rewrite_stream_info(copy("wide"), "Color", widen)
    with sqlite3.connect(copy("text_metadata")) as connection:
        connection.execute("UPDATE messages SET data = CAST(data AS TEXT) WHERE topic_id IN "
                           "(SELECT id FROM topics WHERE name LIKE '%metadata')")
    return made


def device_file_attacks(folder: Path) -> list[Attack]:
    """`gngdt run` on each odd RealSense recording: exit 2 naming the file, no traceback."""
    rows = []
    recordings = odd_realsense_recordings(folder / "recordings")
    for name in ("huge", "wide", "text_metadata"):
        ran = run([*GNGDT, "run", str(recordings[name]), "--fast", "--save",
                   str(folder / f"{name}.rrd")], folder / f"run-{name}.log")
        rows.append(attack(f"RealSense .db3: {name.replace('_', ' ')}", {"run": ran},
                           line_with(ran.output, "refused", "BLOB", "SDK")[:90]))
    return rows


# ----------------------------------------------------------------------------- all of them
def door_attacks(folder: Path | None = None) -> list[Attack]:
    """Every attack of issue 38, in a fresh folder; one row each."""
    folder = folder or Path(tempfile.mkdtemp(prefix="bench-doors-"))
    rows = []
    for part in (device_file_attacks,):
        part_folder = folder / part.__name__
        part_folder.mkdir()
        rows += part(part_folder)
    print(f"logs: {folder}")
    return rows
