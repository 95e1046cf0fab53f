"""Where a run's live outputs can be found -- rerun's web viewer (``--serve``), the Foxglove
WebSocket (``--foxglove``), the ROS 2 node (``--ros2``) -- said once they are up and again in
the summary, and how long they serve after a file ends (``--linger``)."""

from __future__ import annotations

import argparse
import logging
import math
import threading
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)

#: what `--linger` without a value means: until Ctrl-C
UNTIL_STOPPED = math.inf
LINGER_ADVICE = ("--linger keeps it serving after the file ends (until Ctrl-C; --linger 60: a "
                 "minute)")


def add_linger_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--linger", nargs="?", const=UNTIL_STOPPED, type=float,
                        metavar="SECONDS",
                        help="keep --serve and --foxglove serving after a file ends, for "
                        "SECONDS or, without a value, until Ctrl-C (default: they close with "
                        "the run)")


def check_linger(args: argparse.Namespace) -> None:
    """ValueError for a ``--linger`` that cannot do anything."""
    if args.linger is None:
        return
    if not args.linger >= 0:
        raise ValueError(f"--linger must be >= 0 seconds, got {args.linger}")
    if not (args.serve or args.foxglove):
        raise ValueError("--linger keeps --serve or --foxglove serving after the file ends: "
                         "give one of them")


@dataclass(frozen=True)
class LiveOutput:
    """A server a run opens: what it is (``label``: the summary's), its address, how to open
    it."""

    name: str
    label: str
    url: str
    how: str

    def line(self) -> str:
        return f"{self.url} ({self.how})"


def live_outputs(args: argparse.Namespace) -> list[LiveOutput]:
    """The servers the run's logger opens (``--serve``, ``--foxglove``), from its options."""
    from gngdt.io.outputs.base import split_bind
    from gngdt.io.outputs.foxglove import DEFAULT_FOXGLOVE_PORT, FOXGLOVE_STEPS, websocket_url
    from gngdt.io.outputs.rerun_sinks import grpc_url, web_viewer_url

    found = []
    if args.serve:
        host = split_bind(args.bind, 0)[0]
        found.append(LiveOutput(
            "rerun web viewer", "web viewer:", web_viewer_url(host, args.grpc_port,
                                                               args.web_port),
            f"open it in a browser; a native viewer: rerun --connect "
            f"{grpc_url(host, args.grpc_port)}"))
    if args.foxglove:
        url = websocket_url(*split_bind(args.bind, DEFAULT_FOXGLOVE_PORT))
        found.append(LiveOutput("Foxglove WebSocket", "foxglove:", url,
                                f"{FOXGLOVE_STEPS} > {url}"))
    return found


def announce(outputs: list[LiveOutput]) -> None:
    """Say where each server is, once it is up."""
    for output in outputs:
        log.info("serving the %s at %s", output.name, output.line())


def linger(outputs: list[LiveOutput], seconds: float, stop: threading.Event) -> None:
    """Keep serving after the file ended: ``seconds`` (inf: until a stop signal)."""
    until = "until Ctrl-C" if seconds == UNTIL_STOPPED else f"for {seconds:g} s more (--linger)"
    for output in outputs:
        log.info("the file ended; still serving the %s at %s %s", output.name, output.line(),
                 until)
    stop.wait(None if seconds == UNTIL_STOPPED else seconds)


def summary_lines(outputs: list[LiveOutput], lingered: float | None, live: bool) -> list[str]:
    """The summary's lines on the servers: their addresses, and whether they closed with a
    file's end (and how to keep them)."""
    lines = []
    for output in outputs:
        lines.append(f"{output.label:<20}{output.line()}")
        if live:
            continue
        lines.append(" " * 20 + ("served after the file ended too (--linger)" if lingered
                                 else f"closed when the file ended; {LINGER_ADVICE}"))
    return lines


def ros2_line(report: dict[str, Any], endpoint: str) -> str:
    """The summary's line on the ROS 2 bridge (``--ros2``): its node, the router it used, its
    topics and what it published (``report``: its `--report`; {} when it wrote none)."""
    if not report:
        return f"ros2:               no report from the bridge (router {endpoint})"
    published = report.get("messages_out") or {}
    counts = ", ".join(f"{stream} {count}" for stream, count in sorted(published.items()))
    routers = ", ".join(report.get("router") or [endpoint])
    total = sum(published.values())
    return (f"ros2:               node {report.get('node')} (domain {report.get('domain')}) on "
            f"the router at {routers}: {total} message{'' if total == 1 else 's'} out "
            f"({counts}) on "
            f"{', '.join(report.get('topics') or [])} (clouds and markers only while a ROS 2 "
            "subscriber takes them)")
