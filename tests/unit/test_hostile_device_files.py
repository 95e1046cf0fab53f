"""RealSense recordings made odd on purpose (issue 38): stream calibrations claiming 65535x65535
(the SDK's alignment then failed on every frame with a RuntimeError that reached the user as a
traceback), or a plausible field of view over 3 billion pixels (the SDK crashed the process),
and metadata rows stored as TEXT instead of BLOB (a TypeError in gngdt's own check). Each is the
file's problem: a RecordingError naming the file and why, nothing read from it."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest
from helpers.realsense import require_pyrealsense

require_pyrealsense()

from hostile_doors import odd_realsense_recordings  # noqa: E402

from gngdt.io.errors import RecordingError  # noqa: E402
from gngdt.io.sources.realsense import RealSenseSource  # noqa: E402


@pytest.fixture(scope="module")
def odd(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return odd_realsense_recordings(tmp_path_factory.mktemp("realsense_odd"))


def test_the_unaltered_recording_reads(odd: dict[str, Path]) -> None:
    assert len(list(RealSenseSource(odd["base"]).frames())) == 3


def test_streams_claiming_65535x65535_are_the_files_problem(odd: dict[str, Path]) -> None:
    source = RealSenseSource(odd["huge"])
    with pytest.raises(RecordingError, match=r"huge\.db3: .*stream calibration refused: .*"
                                             r"field of view"):
        list(source.frames())
    source.close()


def test_a_stream_over_the_pixel_limit_is_refused_before_the_sdk_decodes_it(
        odd: dict[str, Path]) -> None:
    """A plausible field of view at 65535x48000 still claims more pixels than any camera's
    (before, the SDK's alignment crashed the process)."""
    with pytest.raises(RecordingError, match=r"wide\.db3: .*exceed the limit of"):
        list(RealSenseSource(odd["wide"]).frames())


def test_metadata_stored_as_text_is_the_files_problem(odd: dict[str, Path]) -> None:
    with pytest.raises(RecordingError, match=r"text_metadata\.db3: .*stored as TEXT, not as "
                                             "BLOB"):
        RealSenseSource(odd["text_metadata"])


@pytest.mark.parametrize("value", ["42", "4.2"])
def test_images_stored_as_anything_but_a_blob_are_the_files_problem(
        odd: dict[str, Path], tmp_path: Path, value: str) -> None:
    path = Path(shutil.copy(odd["base"], tmp_path / "odd.db3"))
    with sqlite3.connect(path) as connection:
        connection.execute(f"UPDATE messages SET data = {value} WHERE id = (SELECT MIN(m.id) "
                           "FROM messages m JOIN topics t ON t.id = m.topic_id "
                           "WHERE t.name LIKE '%Depth_0/image/data%')")
    with pytest.raises(RecordingError, match="not as BLOB"):
        RealSenseSource(path)
