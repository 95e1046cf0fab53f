"""A live camera tracked on every frame (``--track --realtime``): the tracker's thread poses each
frame as it comes, the learner learns the frames the time allows, and every frame sent is
accounted for: posed, lost (and why) or dropped before the tracker reached it."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
GNGDT = [sys.executable, "-m", "gngdt.services.cli"]
FRAMES = 45


@pytest.fixture(scope="module")
def walk_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("walk") / "walk.mcap"
    subprocess.run([*GNGDT, "record", "synth", "--scene", "tabletop_walk", "--frames",
                    str(FRAMES), "--width", "320", "--height", "240", "--out", str(path),
                    "--log-level", "WARNING"], check=True, timeout=300)
    return path


@pytest.mark.timeout(600)
def test_every_frame_of_a_live_walk_is_posed_lost_or_dropped(walk_recording: Path,
                                                            tmp_path: Path) -> None:
    completed = subprocess.run(
        [*GNGDT, "run", str(walk_recording), "--track", "--realtime", "--save",
         str(tmp_path / "live.rrd")], cwd=REPO_ROOT, capture_output=True, text=True, timeout=400)
    summary = completed.stdout
    assert completed.returncode == 0, summary + completed.stderr
    assert "mode:               real time (--realtime)" in summary
    sent = int(re.search(r"frames sent:\s+(\d+)", summary).group(1))
    learned = int(re.search(r"frames learned:\s+(\d+)", summary).group(1))
    tracking = re.search(r"tracking:\s+(\d+) of (\d+) frames posed \(\d+%\); (\d+) lost", summary)
    assert tracking is not None, summary
    posed, of, lost = (int(value) for value in tracking.groups())
    dropped = re.search(r"(\d+) not reached in time", summary)
    dropped = int(dropped.group(1)) if dropped else 0
    assert sent == of == FRAMES
    assert posed + lost + dropped == sent, summary  # every frame accounted for
    assert 1 <= learned <= posed, summary  # learned frames are posed ones
    assert "Traceback" not in completed.stdout + completed.stderr
