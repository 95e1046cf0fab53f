"""Where the logger's rerun stream goes, kept within bounds: a ``.rrd`` file that stops growing
at a size cap or when the disk fills up (the logger goes on serving and says so), and a web
viewer served on loopback unless asked otherwise.

rerun's in-process server (``serve_grpc``/``serve_web_viewer``) always listens on every
interface; its CLI takes ``--bind``, so ``--serve`` runs ``rerun --serve-web --bind ADDRESS`` as
a child that dies with the logger, and logs to it over gRPC.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

DEFAULT_BIND = "127.0.0.1"
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090
#: what the served viewer keeps for viewers that connect late
SERVER_MEMORY_LIMIT = "512MB"
DEFAULT_MAX_RRD_MB = 4096
DEFAULT_MIN_FREE_MB = 256
#: a flush of one second of data that takes longer than this means the file cannot be written
FLUSH_TIMEOUT_S = 10.0


#: runs a non-Python command so that it dies with the process that started it (self-contained:
#: imports nothing from the current folder)
_TRAMPOLINE = """
import ctypes, os, signal, sys
if sys.platform.startswith("linux"):
    ctypes.CDLL(None).prctl(1, signal.SIGTERM, 0, 0, 0)
if os.getppid() != int(sys.argv[1]):
    sys.exit(1)
os.execvp(sys.argv[2], sys.argv[2:])
"""


def orphan_proof(command: list[str]) -> list[str]:
    """``command`` wrapped so that it gets SIGTERM when this process exits, however it exits
    (the death signal survives ``exec``)."""
    return [sys.executable, "-P", "-c", _TRAMPOLINE, str(os.getpid()), *command]


class NullRecording:
    """Stands in for the ``rr.RecordingStream`` once writing has stopped: logs go nowhere."""

    def __getattr__(self, name: str) -> Any:
        return lambda *args, **kwargs: None


class RrdFile:
    """The ``.rrd`` a logger writes: flushed every ``flush_every_s``; writing stops, said once,
    when the file reaches ``max_bytes`` (0: no cap; it may pass it by what was logged but not
    yet written), when fewer than ``min_free_bytes`` are free on its file system, or when a write
    fails (a full disk); the logger keeps running.

    ``owner.rec`` is the recording stream its logging goes through; it is swapped for a
    :class:`NullRecording` when writing stops.
    """

    def __init__(self, owner: Any, path: Path, max_bytes: int, min_free_bytes: int,
                 flush_every_s: float = 1.0) -> None:
        self.owner = owner
        self.path = path
        self.max_bytes = max_bytes
        self.min_free_bytes = min_free_bytes
        self.flush_every_s = flush_every_s
        self.recording = owner.rec
        self.stopped = ""
        self.failed = False
        self._last_flush = time.monotonic()

    def tick(self) -> None:
        """Check the size (cheap: call it after every message); every ``flush_every_s``, flush
        and check the free space and the write itself."""
        if self.stopped:
            return
        size = self.path.stat().st_size if self.path.exists() else 0
        if self.max_bytes and size >= self.max_bytes:
            self._stop(f"it reached {size / 1e6:.0f} MB (--max-rrd-mb {self.max_bytes // 10**6})")
            return
        if time.monotonic() - self._last_flush < self.flush_every_s:
            return
        self._last_flush = time.monotonic()
        try:
            self.recording.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as error:  # the file sink could not write (disk full, quota)
            self.failed = True
            self._stop(f"writing it failed ({error}; is the disk full?)")
            return
        free = shutil.disk_usage(self.path.parent).free
        if free < self.min_free_bytes:
            self._stop(f"only {free / 1e6:.0f} MB are free on its disk "
                       f"(--min-free-mb {self.min_free_bytes // 10**6})")

    def _stop(self, reason: str) -> None:
        self.stopped = reason
        self.owner.rec = NullRecording()
        log.error("stopped writing %s: %s; still running, nothing more is recorded", self.path,
                  reason)
        if not self.failed:
            self._close_file()

    def _close_file(self) -> None:
        self.recording.flush(timeout_sec=FLUSH_TIMEOUT_S)
        self.recording.disconnect()  # writes the footer: a complete, readable .rrd

    def close(self) -> None:
        """Flush and finish the file; after a failed write rerun cannot finish it (its flush
        would wait forever), so nothing is attempted: see :func:`exit_now_if_stuck`."""
        if not self.stopped:
            self._close_file()


def exit_now_if_stuck(stuck: bool, code: int) -> int:
    """After a failed write (``stuck``: `RrdFile.failed`) rerun's exit handler waits forever on
    its dead file sink: leave at once, as a kill would, once everything else is closed."""
    if not stuck:
        return code
    import os

    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def client_host(bind: str) -> str:
    """Where a client on this machine reaches a server bound to ``bind`` (any address:
    loopback)."""
    return "127.0.0.1" if bind in ("0.0.0.0", "::", "") else bind


def url_host(bind: str) -> str:
    """`client_host` as a URL holds it (an IPv6 address in brackets)."""
    host = client_host(bind)
    return f"[{host}]" if ":" in host else host


def grpc_url(bind: str, grpc_port: int) -> str:
    """The gRPC server a viewer connects to (``rerun --connect URL``)."""
    return f"rerun+http://{url_host(bind)}:{grpc_port}/proxy"


def web_viewer_url(bind: str, grpc_port: int, web_port: int) -> str:
    """The page to open in a browser: the web viewer, connected to the gRPC server (as
    ``rerun --serve-web`` words it)."""
    from urllib.parse import quote

    return f"http://{url_host(bind)}:{web_port}?url={quote(grpc_url(bind, grpc_port), safe='')}"


class ViewerServer:
    """``rerun --serve-web`` bound to one address: a gRPC proxy the logger logs to, and the web
    viewer; a child process that dies with this one."""

    def __init__(self, bind: str = DEFAULT_BIND, grpc_port: int = DEFAULT_GRPC_PORT,
                 web_port: int = DEFAULT_WEB_PORT, binary: str | None = None) -> None:
        self.bind = bind
        self.grpc_port = grpc_port
        self.web_port = web_port
        check_ports_free(bind, {"--grpc-port": grpc_port, "--web-port": web_port})
        self._output = tempfile.TemporaryFile()
        command = [binary or rerun_binary(), "--serve-web", "--bind", bind,
                   "--port", str(grpc_port), "--web-viewer-port", str(web_port),
                   "--server-memory-limit", SERVER_MEMORY_LIMIT]
        self.process = subprocess.Popen(orphan_proof(command), stdin=subprocess.DEVNULL,
                                        stdout=self._output, stderr=subprocess.STDOUT)

    @property
    def grpc_url(self) -> str:
        return grpc_url(self.bind, self.grpc_port)

    @property
    def web_url(self) -> str:
        return web_viewer_url(self.bind, self.grpc_port, self.web_port)

    @property
    def _host(self) -> str:
        return client_host(self.bind)

    def wait_ready(self, timeout_s: float = 60.0) -> None:
        """Until both ports accept connections; ``OSError`` with rerun's output if it failed."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise OSError(f"the rerun viewer server stopped (exit {self.process.returncode}; "
                              f"ports {self.grpc_port}/{self.web_port} in use?): {self._tail()}")
            if all(_accepts(self._host, port) for port in (self.grpc_port, self.web_port)):
                return
            time.sleep(0.1)
        self.stop()
        raise OSError(f"the rerun viewer server did not come up in {timeout_s:.0f} s")

    def _tail(self) -> str:
        self._output.seek(0)
        return self._output.read().decode(errors="replace").strip()[-500:]

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._output.close()


def rerun_binary() -> str:
    """The rerun CLI binary rerun-sdk ships (run directly: ``python -m rerun`` would start it as
    a grandchild, which a death signal of ours would not reach; ``RERUN_CLI_PATH``, read at the
    command line's edge, names another: `ViewerServer`'s ``binary``)."""
    import importlib.util
    import os

    spec = importlib.util.find_spec("rerun_cli")
    if spec is None or spec.origin is None:
        raise OSError("the rerun CLI is not installed (pip install rerun-sdk)")
    folder = Path(spec.origin).parent
    bundled = folder / "Rerun.app" / "Contents" / "MacOS" / "Rerun"  # macOS wheels
    binary = bundled if bundled.exists() else folder / ("rerun.exe" if os.name == "nt" else "rerun")
    if not binary.exists():
        raise OSError(f"the rerun CLI binary is missing: {binary}")
    return str(binary)


def port_in_use(host: str, port: int) -> bool:
    """Whether a process listens on ``port`` of ``host`` already (binding it as a server would:
    a port left in TIME_WAIT is free)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError:
            return True
    return False


def check_ports_free(host: str, ports: dict[str, int]) -> None:
    """OSError naming the option of the first port (``{"--web-port": 9090}``) something already
    listens on: a viewer server started there would fail, and the logger would stream into
    whatever holds it (another run's viewer)."""
    for option, port in ports.items():
        if port_in_use(host, port):
            raise OSError(f"port {port} on {host} is in use (another `gngdt run --serve` or a "
                          f"rerun viewer?); choose a free one with {option}")


def _accepts(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.settimeout(0.5)
        return probe.connect_ex((host, port)) == 0
