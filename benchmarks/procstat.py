"""Processes of the benchmarks (Linux): gngdt services started in the background, and a live
process's memory and CPU from /proc."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]


def gngdt(*arguments: str, log: Path) -> subprocess.Popen:
    """``gngdt <arguments>`` started in its own session from the repository, output to ``log``."""
    with open(log, "wb") as output:
        return subprocess.Popen([sys.executable, "-m", "gngdt.services.cli", *arguments],
                                cwd=REPO_ROOT, stdout=output, stderr=subprocess.STDOUT,
                                start_new_session=True)


def wait_until(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll ``condition`` until it holds; exit the benchmark naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    raise SystemExit(f"timed out waiting for {what}")


def status_mb(pid: int, field: str) -> float:
    """A memory field of /proc/<pid>/status in MB: ``VmRSS`` (resident now), ``VmHWM`` (peak
    resident); 0 when the process is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a live process, seconds; 0 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@contextmanager
def busy_processes(count: int = 2) -> Iterator[None]:
    """``count`` processes spinning on the CPU (a machine busy with other work), each stopped
    by pid on the way out."""
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                for _ in range(count)]
    try:
        yield
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
