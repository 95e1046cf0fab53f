"""What a service did, for whoever started it: with ``--report FILE`` a service writes there, as it
exits, one JSON object (the logger: each output, where it went and why it stopped early; the
ROS 2 bridge: its node, router, topics and messages out). `gngdt run` gives its logger and its
bridge one each and says what they hold in its summary: a typed account, not a log to scrape.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: what a report holds at most (a real one is under 4 kB)
MAX_REPORT_BYTES = 1 << 20


def add_report_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """``--report FILE``; ``what``: what the service's report holds."""
    parser.add_argument("--report", type=Path, metavar="FILE",
                        help=f"on exit, write {what} into FILE (JSON; `gngdt run` reads it for "
                        "its summary)")


def write_report(path: Path | None, values: dict[str, Any]) -> None:
    """``values`` as JSON into ``path`` (nothing without one), whole or not at all; a failure is
    logged, never raised: the service's work is done."""
    if path is None:
        return
    partial = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        partial.write_text(json.dumps(values, indent=2, sort_keys=True))
        os.replace(partial, path)
    except OSError as error:
        log.warning("cannot write the report %s: %s", path, error)
        partial.unlink(missing_ok=True)


def read_report(path: Path) -> dict[str, Any]:
    """A report's values; {} when there is none (the service did not get to write it) or it is
    not a report."""
    try:
        if path.stat().st_size > MAX_REPORT_BYTES:
            return {}
        values = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return {}
    return values if isinstance(values, dict) else {}
