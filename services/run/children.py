"""The services of one `gngdt run`: child processes whose output goes to a log file each, started
with their settings, waited for while they start (as long as each shows progress) and stopped
by pid."""

from __future__ import annotations

import logging
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from gngdt.core.learner.warm_up import PROGRESS_PHRASE
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.settings import write_settings

if TYPE_CHECKING:
    from gngdt.services.plumbing.roles import RunAccess
    from gngdt.services.run.observe import Observed

log = logging.getLogger(__name__)


@dataclass(eq=False)  # a process: equal only to itself (and hashable)
class Child:
    """One service process; its stderr goes to a file whose tail is shown when it fails."""

    name: str
    process: subprocess.Popen
    stderr_path: Path
    stderr_file: IO[bytes]

    def stderr_tail(self, lines: int = 20) -> str:
        text = self.stderr_path.read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])

    def interrupt(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)

    def stop(self, timeout_s: float) -> int:
        """Wait for the process, escalating SIGINT -> SIGKILL after ``timeout_s``."""
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.interrupt()
        try:
            return self.process.wait(10.0)
        except subprocess.TimeoutExpired:
            log.error("%s did not stop; killing it", self.name)
            self.process.kill()
            return self.process.wait()


class Pipeline:
    """The child processes of one run."""

    def __init__(self, access: RunAccess, log_dir: Path, log_level: str) -> None:
        self.access = access
        self.log_dir = log_dir
        self.log_level = log_level
        self.children: list[Child] = []
        self.interrupted = False

    def start(self, name: str, arguments: list[str],
              settings: dict[str, Any] | None = None) -> Child:
        """Start the service ``name`` with ``arguments`` and its ``settings`` (its options'
        values: a file beside its log, `gngdt.services.plumbing.settings`)."""
        if settings is not None:
            path = write_settings(self.log_dir / f"{name}.settings.json", settings)
            arguments = [*arguments, "--settings", str(path)]
        # -P: the user's current folder is not put first on the children's import path
        command = [sys.executable, "-P", "-m", "gngdt.services.cli", name, *arguments,
                   "--zenoh-config", str(self.access.client_file(name)),
                   "--log-level", self.log_level]
        stderr_path = self.log_dir / f"{name}.log"
        stderr_file = open(stderr_path, "wb")  # closed in Pipeline.close()
        env = lifecycle.child_environment()  # the child dies with this process
        log.debug("starting %s", " ".join(command))
        process = subprocess.Popen(command, stdout=stderr_file, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, env=env, start_new_session=True)
        child = Child(name, process, stderr_path, stderr_file)
        self.children.append(child)
        return child

    def failed(self) -> Child | None:
        """The first child that exited with an error, if any (not counting our own SIGINT)."""
        interrupted_codes = (130, -signal.SIGINT) if self.interrupted else ()
        for child in self.children:
            code = child.process.poll()
            if code is not None and code != 0 and code not in interrupted_codes:
                return child
        return None

    def interrupt_all(self) -> None:
        self.interrupted = True
        for child in self.children:
            child.interrupt()

    def close(self) -> None:
        for child in self.children:
            if child.process.poll() is None:
                child.process.kill()
                child.process.wait()
            child.stderr_file.close()


def wait_until(condition, timeout_s: float, stop: threading.Event, pipeline: Pipeline) -> bool:
    """Poll ``condition`` until true; False on timeout, stop request or a failed child."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not stop.is_set() and pipeline.failed() is None:
        if condition():
            return True
        time.sleep(0.05)
    return bool(condition())


class StartupProgress:
    """Whether a starting child is making progress: the CPU time it used, the lines it logged
    (its start-up steps, e.g. "compiling kernels 2/4", are shown as they come)."""

    def __init__(self, child: Child) -> None:
        self.child = child
        self.cpu_ticks = -1
        self.log_bytes = 0
        self.last_progress = time.monotonic()

    def advanced(self) -> bool:
        """Did the child use CPU or log anything since the last call? New start-up steps in its
        log are shown."""
        ticks = cpu_ticks(self.child.process.pid)
        size = self.child.stderr_path.stat().st_size if self.child.stderr_path.exists() else 0
        moved = ticks != self.cpu_ticks or size != self.log_bytes
        if size > self.log_bytes:
            with open(self.child.stderr_path, "rb") as file:
                file.seek(self.log_bytes)
                for line in file.read(size - self.log_bytes).decode(errors="replace").splitlines():
                    if PROGRESS_PHRASE in line:
                        log.info("%s: %s", self.child.name,
                                 line[line.index(PROGRESS_PHRASE):])
        self.cpu_ticks, self.log_bytes = ticks, size
        if moved:
            self.last_progress = time.monotonic()
        return moved


def cpu_ticks(pid: int) -> int:
    """CPU time a process has used (user + system, in clock ticks; Linux /proc), -1 if gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return -1
    return int(fields[11]) + int(fields[12])


def wait_for_startup(starting: dict[Child, str], observed: Observed, silence_s: float,
                     stop: threading.Event, pipeline: Pipeline) -> Child | None:
    """Wait until every child in ``starting`` has declared its liveliness token, as long as each
    keeps making progress; the first child silent for ``silence_s`` (None: all came up, or a
    stop signal or a failed child ended the wait)."""
    progress = {child: StartupProgress(child) for child in starting}
    while not stop.is_set() and pipeline.failed() is None:
        waiting = [child for child, token in starting.items() if not observed.has_alive(token)]
        if not waiting:
            return None
        for child in waiting:
            watch = progress[child]
            if not watch.advanced() and time.monotonic() - watch.last_progress > silence_s:
                return child
        time.sleep(0.1)
    return None
