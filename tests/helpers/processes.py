"""Helpers for tests of real processes: their logs, waiting on them, and what they hold, read
from /proc (their sockets and children; Linux); commands wrapped to measure or limit them."""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Callable
from pathlib import Path


def _sockets_of(pid: int) -> set[str]:
    """Socket inodes the process holds open."""
    inodes = set()
    for descriptor in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(descriptor)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:["):-1])
    return inodes


def _ipv4(hex_address: str) -> str:
    address, port = hex_address.split(":")
    octets = bytes.fromhex(address)[::-1]  # /proc/net is in host (little-endian) order
    return f"{'.'.join(str(octet) for octet in octets)}:{int(port, 16)}"


def bound_sockets(pid: int) -> list[tuple[str, str, str]]:
    """(protocol, local address, state) of every TCP listener and UDP socket of ``pid``."""
    inodes = _sockets_of(pid)
    found = []
    for protocol in ("tcp", "tcp6", "udp", "udp6"):
        lines = Path(f"/proc/net/{protocol}").read_text().splitlines()[1:]
        for line in lines:
            columns = line.split()
            local, state, inode = columns[1], columns[3], columns[9]
            if inode not in inodes:
                continue
            listening = state == "0A"  # TCP_LISTEN
            if protocol.startswith("udp") or listening:
                shown = _ipv4(local) if protocol in ("tcp", "udp") else local
                found.append((protocol, shown, "listen" if listening else "bound"))
    return found


def children(pid: int) -> list[int]:
    """Pids whose parent is ``pid``."""
    found = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            lines = status.read_text().splitlines()
        except OSError:
            continue
        fields = dict(line.split(":\t", 1) for line in lines if ":\t" in line)
        if int(fields.get("PPid", "0").strip()) == pid:
            found.append(int(status.parent.name))
    return found


def alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie, exited but not reaped, is not alive)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[0]
    except OSError:
        return False
    return state != "Z"


def command_line(pid: int) -> list[str]:
    """The arguments ``pid`` was started with ([] once it is gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")[:-1]
    except OSError:
        return []


def log_text(process) -> str:
    """What a process started by the ``spawn`` fixture has written so far."""
    return Path(process.log_path).read_text(errors="replace")


def wait_exit(process: subprocess.Popen, timeout_s: float) -> int:
    """``process``'s exit status; AssertionError with its log if it runs past ``timeout_s``."""
    try:
        return process.wait(timeout_s)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"process did not exit:\n{log_text(process)}") from None


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll ``condition`` until true; AssertionError naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


#: runs a command and prints the peak resident memory of it and its children ("peak_rss_kb N")
_PEAK_RSS = (
    "import resource, subprocess, sys\n"
    "code = subprocess.call(sys.argv[1:])\n"
    "print('peak_rss_kb', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, flush=True)\n"
    "sys.exit(code)\n"
)


def with_peak_rss(command: list[str]) -> list[str]:
    """``command`` run so that its output ends with its peak RSS (see :func:`peak_rss_mb`)."""
    import sys

    return [sys.executable, "-c", _PEAK_RSS, *command]


def peak_rss_mb(output: str) -> float:
    """The peak RSS a :func:`with_peak_rss` command printed, in MB."""
    line = next(line for line in output.splitlines() if line.startswith("peak_rss_kb "))
    return int(line.split()[1]) / 1024


_DEFAULT_SIGHUP = (
    "import os, signal, sys\n"
    "signal.signal(signal.SIGHUP, signal.SIG_DFL)\n"
    "os.execv(sys.argv[1], sys.argv[1:])\n"
)


def with_default_sighup(command: list[str]) -> list[str]:
    """``command`` with SIGHUP's default disposition, as a terminal's child has: a suite run
    under ``nohup`` hands its children SIGHUP ignored, which gngdt honours on purpose; the
    command's first element must be an executable's path."""
    import sys

    return [sys.executable, "-c", _DEFAULT_SIGHUP, *command]


#: runs gngdt with writes limited to a few megabytes a file, as a full disk would stop them
FILE_SIZE_LIMITED = (
    "import os, resource, signal, sys\n"
    "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a kill\n"
    "resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))\n"
    "os.execv(sys.executable, [sys.executable, '-m', 'gngdt.services.cli', *sys.argv[1:]])\n"
)
