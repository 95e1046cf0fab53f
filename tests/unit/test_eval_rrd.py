"""``gngdt eval rrd`` on .rrd files written with rerun's own API (the real format)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gngdt.eval.rrd import RrdError, read_metrics
from gngdt.services.cli import main as gngdt_main


def _write_run(path: Path, frames: int) -> dict[str, np.ndarray]:
    """A small logged run: nodes grow, steps/s and latency vary, clusters per topology."""
    import rerun as rr

    rng = np.random.default_rng(0)
    series = {
        "nodes": np.minimum(2 + 20 * np.arange(frames), 150).astype(float),
        "steps_per_s": rng.uniform(4e5, 6e5, frames),
        "latency_ms": rng.uniform(5, 40, frames),
        "clusters/col": rng.integers(3, 7, frames).astype(float),
    }
    recording = rr.RecordingStream("gngdt-test", recording_id="eval-rrd-test")
    recording.set_sinks(rr.FileSink(str(path)))
    for frame in range(frames):
        recording.set_time("frame", sequence=frame)
        recording.set_time("capture_time", timestamp=1_700_000_000 + frame / 30)
        for name, values in series.items():
            recording.log(f"metrics/{name}", rr.Scalars(values[frame]))
        recording.log("world/gng/nodes", rr.Points3D(rng.normal(size=(5, 3))))
    recording.flush()
    recording.disconnect()
    return series


def test_read_metrics_returns_every_series_in_frame_order(tmp_path) -> None:
    expected = _write_run(tmp_path / "run.rrd", 12)
    series = read_metrics(tmp_path / "run.rrd")
    assert set(series) == set(expected)
    for name, values in expected.items():
        np.testing.assert_array_equal(series[name].frames, np.arange(12))
        np.testing.assert_allclose(series[name].values, values)
    capture = series["nodes"].capture_time_ns
    assert capture is not None
    assert (capture[-1] - capture[0]) / 1e9 == pytest.approx(11 / 30, abs=1e-6)


def test_eval_rrd_cli_writes_report_json_and_plot(tmp_path) -> None:
    expected = _write_run(tmp_path / "run.rrd", 8)
    out = tmp_path / "report"
    assert gngdt_main(["eval", "rrd", str(tmp_path / "run.rrd"), "--out", str(out)]) == 0
    data = json.loads((out / "rrd.json").read_text())
    assert data["frames"] == 8
    nodes = data["metrics"]["nodes"]["summary"]
    assert nodes["last"] == expected["nodes"][-1]
    assert nodes["max"] == expected["nodes"].max()
    assert data["metrics"]["latency_ms"]["summary"]["mean"] == pytest.approx(
        expected["latency_ms"].mean()
    )
    markdown = (out / "rrd.md").read_text()
    assert "| nodes |" in markdown and "rrd_metrics.png" in markdown
    assert (out / "rrd_metrics.png").stat().st_size > 1000


def test_eval_rrd_rejects_missing_and_garbage_files(tmp_path, capsys) -> None:
    with pytest.raises(RrdError, match="no such file"):
        read_metrics(tmp_path / "absent.rrd")
    garbage = tmp_path / "garbage.rrd"
    garbage.write_bytes(b"not an rrd file at all")
    assert gngdt_main(["eval", "rrd", str(garbage), "--out", str(tmp_path / "o")]) == 2
    assert "garbage.rrd" in capsys.readouterr().err


def test_eval_rrd_without_metrics_is_a_clear_error(tmp_path, capsys) -> None:
    import rerun as rr

    path = tmp_path / "points_only.rrd"
    recording = rr.RecordingStream("gngdt-test", recording_id="no-metrics")
    recording.set_sinks(rr.FileSink(str(path)))
    recording.log("world/points", rr.Points3D(np.zeros((3, 3))))
    recording.flush()
    recording.disconnect()
    assert gngdt_main(["eval", "rrd", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "no 'metrics/<name>' scalars" in capsys.readouterr().err


