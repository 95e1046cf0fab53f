"""Writing reports: Markdown tables, mean ± std cells, and a JSON file holding every figure."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np


def mean_std(values: Iterable[float]) -> dict[str, float]:
    """Mean and (population, ddof=0) standard deviation of finite ``values``; NaN when none.

    Returns ``{"mean", "std", "n"}``; non-finite values are left out (``n`` counts the rest).
    """
    array = np.asarray([v for v in values if v is not None], dtype=np.float64)
    array = array[np.isfinite(array)]
    if array.size == 0:
        return {"mean": math.nan, "std": math.nan, "n": 0}
    return {"mean": float(array.mean()), "std": float(array.std()), "n": int(array.size)}


def format_mean_std(stats: dict[str, float] | None, digits: int = 3) -> str:
    """``"7.341 ± 0.022"`` for a ``mean_std`` dict; ``"—"`` when missing or NaN."""
    if stats is None or not math.isfinite(stats.get("mean", math.nan)):
        return "—"
    return f"{stats['mean']:.{digits}f} ± {stats['std']:.{digits}f}"


def format_number(value: float | None, digits: int = 3) -> str:
    """A number with ``digits`` decimals, ``"—"`` for None/NaN."""
    if value is None or not math.isfinite(float(value)):
        return "—"
    return f"{float(value):.{digits}f}"


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """A GitHub-flavoured Markdown table (cells converted with ``str``; ``|`` escaped)."""

    def cell(value: object) -> str:
        return str(value).replace("|", "\\|")

    lines = [
        "| " + " | ".join(cell(h) for h in headers) + " |",
        "|" + "|".join("---" for _ in headers) + "|",
    ]
    lines.extend("| " + " | ".join(cell(v) for v in row) + " |" for row in rows)
    return "\n".join(lines)


def to_jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays, tuples and Paths (recursively) into JSON-ready values.

    Non-finite floats become ``None`` so the file stays strict JSON.
    """
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_report(
    out_dir: Path, stem: str, markdown: str, data: dict[str, Any]
) -> tuple[Path, Path]:
    """Write ``<stem>.md`` and ``<stem>.json`` into ``out_dir`` (created); return both paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    markdown_path = out_dir / f"{stem}.md"
    json_path = out_dir / f"{stem}.json"
    markdown_path.write_text(markdown.rstrip() + "\n", encoding="utf-8")
    json_path.write_text(
        json.dumps(to_jsonable(data), indent=2, allow_nan=False) + "\n", encoding="utf-8"
    )
    return markdown_path, json_path
