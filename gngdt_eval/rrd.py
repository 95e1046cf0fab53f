"""What a logged run did: the learner's ``metrics/<name>`` scalars read back from an ``.rrd`` file.

Reads with rerun's own reader (``rerun.chunk.RrdReader``), so anything the viewer can open is read
the same way here. Every entity under ``metrics/`` holding ``Scalars`` becomes one series indexed by
the ``frame`` timeline (and ``capture_time`` where logged).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.eval.report import format_number, markdown_table, write_report

log = logging.getLogger(__name__)

METRICS_PREFIX = "metrics/"
SCALARS_COLUMN = "Scalars:scalars"


class RrdError(ValueError):
    """An .rrd file that cannot be read or holds no metrics."""


@dataclass
class MetricSeries:
    """One scalar metric over time.

    frames: (T,) int64 values of the ``frame`` timeline (sorted; -1 where a row had none).
    capture_time_ns: (T,) int64 nanoseconds since the epoch, or None when not logged.
    values: (T,) float64, the scalar at each row (first scalar when a row held several).
    """

    name: str
    frames: np.ndarray
    capture_time_ns: np.ndarray | None
    values: np.ndarray

    def summary(self) -> dict[str, float]:
        """count, first, last, min, mean, median, p99, max of the finite values."""
        finite = self.values[np.isfinite(self.values)]
        if finite.size == 0:
            return {"count": 0}
        return {
            "count": int(finite.size),
            "first": float(finite[0]),
            "last": float(finite[-1]),
            "min": float(finite.min()),
            "mean": float(finite.mean()),
            "median": float(np.median(finite)),
            "p99": float(np.percentile(finite, 99)),
            "max": float(finite.max()),
        }


def read_metrics(path: str | Path) -> dict[str, MetricSeries]:
    """All ``metrics/<name>`` scalar series in the .rrd at ``path``, keyed by ``<name>``.

    Raises ``RrdError`` naming the file when it is missing or unreadable.
    """
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise RrdError(f"{path}: no such file")
    try:
        store = RrdReader(str(path)).stream().collect()
        chunks = list(store.stream())
    except Exception as error:  # rerun raises its own exception types for corrupt files
        raise RrdError(f"{path}: not a readable .rrd file ({error})") from error

    pieces: dict[str, list[tuple[np.ndarray, np.ndarray | None, np.ndarray]]] = {}
    for chunk in chunks:
        # rerun escapes characters such as "+" in entity path parts ("col\+nor")
        entity = re.sub(r"\\(.)", r"\1", str(chunk.entity_path)).lstrip("/")
        if not entity.startswith(METRICS_PREFIX) or chunk.num_rows == 0:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if SCALARS_COLUMN not in names:
            continue
        values = _first_scalars(batch.column(SCALARS_COLUMN))
        frames = (
            _int_column(batch.column("frame"))
            if "frame" in names
            else np.full(len(values), -1, dtype=np.int64)
        )
        capture = _int_column(batch.column("capture_time")) if "capture_time" in names else None
        pieces.setdefault(entity[len(METRICS_PREFIX) :], []).append((frames, capture, values))

    series: dict[str, MetricSeries] = {}
    for name, parts in sorted(pieces.items()):
        frames = np.concatenate([p[0] for p in parts])
        values = np.concatenate([p[2] for p in parts])
        captures = (
            np.concatenate([p[1] for p in parts]) if all(p[1] is not None for p in parts) else None
        )
        order = np.argsort(frames, kind="stable")
        # one value per frame, the last logged: at the end of a stream the learner publishes
        # its settled network again for the last frame
        last_of_frame = np.append(frames[order][1:] != frames[order][:-1], True)
        last_of_frame |= frames[order] < 0  # no frame timeline: keep every value
        order = order[last_of_frame]
        series[name] = MetricSeries(
            name=name,
            frames=frames[order],
            capture_time_ns=None if captures is None else captures[order],
            values=values[order],
        )
    return series


def _first_scalars(column: Any) -> np.ndarray:
    """(rows,) float64: the first scalar of each row of a list<double> column (NaN if empty)."""
    rows = column.to_pylist()
    return np.array([float(row[0]) if row else np.nan for row in rows], dtype=np.float64)


def _int_column(column: Any) -> np.ndarray:
    """(rows,) int64 of an int64 or timestamp[ns] column, nulls as -1."""
    import pyarrow as pa

    if pa.types.is_timestamp(column.type):
        column = column.cast(pa.int64())
    return column.fill_null(-1).to_numpy(zero_copy_only=False).astype(np.int64)


def evaluate_rrd(path: str | Path, out_dir: str | Path) -> dict[str, Any]:
    """Summarise a logged run into ``out_dir``: ``rrd.md``, ``rrd.json`` and one PNG of all metrics.

    Returns the JSON data. Raises ``RrdError`` when the file holds no ``metrics/`` scalars.
    """
    from gngdt.eval.plots import plot_metric_series

    path = Path(path)
    out_dir = Path(out_dir)
    series = read_metrics(path)
    if not series:
        raise RrdError(f"{path}: no '{METRICS_PREFIX}<name>' scalars (was it logged by gngdt?)")
    out_dir.mkdir(parents=True, exist_ok=True)
    plot_path = plot_metric_series(
        {name: (s.frames, s.values) for name, s in series.items()},
        out_dir / "rrd_metrics.png",
        title=f"learner metrics over frames — {path.name}",
    )
    summaries = {name: s.summary() for name, s in series.items()}
    frames_seen = sorted({int(f) for s in series.values() for f in s.frames if f >= 0})
    duration_s = _capture_duration_s(series)
    data = {
        "rrd": str(path),
        "frames": len(frames_seen),
        "capture_duration_s": duration_s,
        "metrics": {
            name: {
                "summary": summaries[name],
                "frame": s.frames,
                "capture_time_ns": s.capture_time_ns,
                "value": s.values,
            }
            for name, s in series.items()
        },
        "plots": [plot_path.name],
    }
    rows = [
        [name]
        + [
            format_number(summaries[name].get(key))
            for key in ("first", "last", "min", "mean", "median", "p99", "max")
        ]
        + [summaries[name].get("count", 0)]
        for name in series
    ]
    markdown = "\n\n".join(
        [
            f"# What the live pipeline did — `{path.name}`",
            f"Read back with `rerun.chunk.RrdReader`: {len(series)} metric series over "
            f"{len(frames_seen)} frames"
            + (f", {duration_s:.2f} s of capture time." if duration_s is not None else "."),
            markdown_table(
                ["metric", "first", "last", "min", "mean", "median", "p99", "max", "rows"], rows
            ),
            f"![metrics over frames]({plot_path.name})",
        ]
    )
    write_report(out_dir, "rrd", markdown, data)
    return data


def _capture_duration_s(series: dict[str, MetricSeries]) -> float | None:
    stamps = [
        s.capture_time_ns[s.capture_time_ns >= 0]
        for s in series.values()
        if s.capture_time_ns is not None
    ]
    stamps = [s for s in stamps if s.size]
    if not stamps:
        return None
    joined = np.concatenate(stamps)
    return float(joined.max() - joined.min()) / 1e9
