"""``gngdt eval rrd`` on .rrd files written with rerun's own API (the real format)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gngdt.eval.rrd import read_metrics
from gngdt.services.cli import main as gngdt_main


@pytest.mark.timeout(240)
def test_eval_rrd_on_a_real_logged_run(tmp_path) -> None:
    """The whole pipeline (`gngdt run`) logs a tiny recording; eval rrd reads what it did."""
    import subprocess
    import sys

    from gngdt.io.mcap.writer import RecordingWriter
    from gngdt.io.synth.render import render_scene

    recording = tmp_path / "tiny.mcap"
    with RecordingWriter(recording) as writer:
        for frame in render_scene("tabletop", 4, width=160, height=120, seed=1):
            writer.write_frame(frame)
    rrd = tmp_path / "run.rrd"
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(recording), "--save", str(rrd),
         "--fast"],
        capture_output=True,
        text=True,
        timeout=200,
    )
    assert completed.returncode == 0, completed.stderr[-2000:]
    series = read_metrics(rrd)
    assert "nodes" in series and "clusters/col+nor" in series
    nodes = series["nodes"].values
    assert len(nodes) >= 1 and nodes[-1] >= 2
    assert np.all(np.diff(series["nodes"].frames) > 0)
    out = tmp_path / "report"
    assert gngdt_main(["eval", "rrd", str(rrd), "--out", str(out)]) == 0
    assert (
        json.loads((out / "rrd.json").read_text())["metrics"]["nodes"]["summary"]["last"]
        == (nodes[-1])
    )
