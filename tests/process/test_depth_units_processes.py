"""A recording whose depth is in the wrong unit (issue 24.6): `gngdt run` no longer exits 0
having learned nothing; it says what probably happened."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(240)
def test_a_run_that_learns_nothing_says_why_and_fails(tmp_path: Path) -> None:
    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    path = tmp_path / "metres.mcap"
    with RecordingWriter(path) as writer:  # depth in whole metres where millimetres belong
        for frame in render_scene("tabletop", 3, width=160, height=120):
            writer.write_frame(replace(frame, depth=np.rint(frame.depth / 1000.0)
                                       .astype(np.uint16)))
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(path), "--fast", "--save",
         str(tmp_path / "run.rrd")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=200)
    assert completed.returncode == 3, completed.stdout + completed.stderr  # nothing learned
    assert "learner:            no status received" in completed.stdout
    assert "the learner learned nothing" in completed.stderr
    assert "depth in another unit" in completed.stderr
    # capture's own words (issue 35.4): the depth check, the frames it sent without a cloud
    assert "WARNING: the median depth is" in completed.stdout
    assert "sent without cloud: 3 frames: no depth between --min-depth" in completed.stdout
