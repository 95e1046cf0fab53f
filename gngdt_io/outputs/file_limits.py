"""How large the logger's files may grow and how much free disk they must leave, declared once
for `gngdt log` and `gngdt run` (the .rrd and the ``--mcap`` file alike): each file stops at its
limit, complete and readable, while the logger goes on, and says why."""

from __future__ import annotations

from typing import Any

from gngdt.io.outputs.rerun_sinks import DEFAULT_MAX_RRD_MB, DEFAULT_MIN_FREE_MB

#: the largest --mcap file by default, MB
DEFAULT_MAX_MCAP_MB = 4096
FILE_LIMITS_TITLE = ("limits of the files written (.rrd, --mcap): a file stops, complete and "
                     "readable, at its limit; the run goes on and its summary says why")


def add_file_limit_arguments(group: Any) -> None:
    """``--max-rrd-mb``, ``--min-free-mb`` and ``--max-mcap-mb`` (into a parser or a group)."""
    group.add_argument("--max-rrd-mb", type=int, default=DEFAULT_MAX_RRD_MB, metavar="MB",
                       help="stop writing the .rrd (a complete file) once it is this large "
                       f"and go on running (default {DEFAULT_MAX_RRD_MB}; 0: no cap)")
    group.add_argument("--min-free-mb", type=int, default=DEFAULT_MIN_FREE_MB, metavar="MB",
                       help="stop writing the .rrd (and the --mcap file) when less than this is "
                       f"free on its disk (default {DEFAULT_MIN_FREE_MB}); a failed write stops "
                       "it too")
    group.add_argument("--max-mcap-mb", type=int, default=DEFAULT_MAX_MCAP_MB, metavar="MB",
                       help="stop writing the MCAP (a complete file) once it is this large and "
                       f"go on running (default {DEFAULT_MAX_MCAP_MB}; 0: no cap); it stops too "
                       "below --min-free-mb, or when a write fails, and stays readable")
