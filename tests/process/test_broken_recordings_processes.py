"""Broken recordings: truncated files, wrong schemas, mismatched sizes, bad depth values, missing
calibration. Each gives a clear message naming the file and the frame, and capture goes on with
the next good frame where one exists (reader's ``on_bad_frame``, and the capture process)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.raw_recordings import HEIGHT, WIDTH, RawRecording


@pytest.mark.timeout(120)
def test_capture_skips_bad_frames_and_sends_the_good_ones(
    run_capture: Callable, tmp_path: Path
) -> None:
    path = tmp_path / "holes.mcap"
    recording = RawRecording(path)
    for index in range(7):
        if index in (1, 4):
            recording.write_frame(index, depth=np.ones((HEIGHT // 2, WIDTH), np.uint16))
        else:
            recording.write_frame(index)
    recording.close()

    output = run_capture(path)

    # the first frame refused for a reason is named; the others are counted, in the log and in
    # the end of stream
    assert "holes.mcap: frame 1: depth 40x15 does not match colour 40x30" in output.log
    assert "2 frames refused: depth 40x15 does not match colour 40x30 (2)" in output.log
    assert len(output.ends) == 1 and output.ends[0].frames_sent == 5
    assert output.ends[0].frames_refused == {"depth 40x15 does not match colour 40x30": 2}
    assert len(output.clouds) == 5
