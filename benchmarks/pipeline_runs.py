"""Pipelines of real processes for the benchmarks: a ``gngdt router`` process admitting only the
run's services (the credentials ``gngdt run`` makes), captures, learners and a logger as its
clients, what they publish observed from a client session, and their CPU read from /proc.

A :class:`Transport` says how large payloads travel on the one host:

- ``network``: shared memory off in every session and the router
  (``transport/shared_memory/enabled: false``): every image and cloud is copied through the
  router's TCP links, the baseline;
- ``zenoh``: zenoh's defaults without gngdt's pools (``GNGDT_SHM_POOL_MB=0``): zenoh copies large
  payloads into its own 16 MiB pool when one is free (how gngdt ran before its pools);
- ``shm``: gngdt's default, each publisher's own pool (``gngdt.services.plumbing.session``).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from procstat import REPO_ROOT, cpu_seconds, status_mb

from gngdt.schemas.wire import ALL_KEYS, CAPTURE, FrameStamp, alive_key
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.environment import SHARED_MEMORY_POOL_ENV
from gngdt.services.plumbing.session import (
    client_config,
    free_tcp_port,
    open_config,
    router_settings,
    settings_file_text,
)
from gngdt.services.run import Child, RunAccess


@dataclass(frozen=True)
class Transport:
    """How payloads travel between the processes of one host (see the module's docstring)."""

    name: str
    shared_memory: bool
    gngdt_pools: bool

    @property
    def environment(self) -> dict[str, str]:
        return {} if self.gngdt_pools else {SHARED_MEMORY_POOL_ENV: "0"}


TRANSPORTS = {
    "network": Transport("network", shared_memory=False, gngdt_pools=False),
    "zenoh": Transport("zenoh", shared_memory=True, gngdt_pools=False),
    "shm": Transport("shm", shared_memory=True, gngdt_pools=True),
}


@dataclass
class CameraSeen:
    """What the observer heard of one camera."""

    status: object = None
    end: object = None
    received_latency_ms: list[float] = field(default_factory=list)


class Observer:
    """A client session of the run: liveliness, every camera's status, end and topology."""

    def __init__(self, client_file: Path, wait_s: float = 60.0) -> None:
        self.lock = threading.Lock()
        self.alive: set[str] = set()
        self.cameras: dict[str, CameraSeen] = {}
        self.session = open_config(client_config(config_file=client_file), wait_s=wait_s)
        self._declared = [
            self.session.liveliness().declare_subscriber(ALL_KEYS, self._on_liveliness,
                                                         history=True),
            self.session.declare_subscriber("gngdt/*/learner/status", self._on_status),
            self.session.declare_subscriber("gngdt/*/eos", self._on_eos),
            self.session.declare_subscriber("gngdt/*/topology", self._on_topology),
        ]

    def camera(self, key: object) -> CameraSeen:
        return self.cameras.setdefault(str(key).split("/")[1], CameraSeen())

    def _on_liveliness(self, sample) -> None:
        import zenoh

        with self.lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(str(sample.key_expr))
            else:
                self.alive.discard(str(sample.key_expr))

    def _on_status(self, sample) -> None:
        from gngdt.schemas.status import decode_status

        status = decode_status(sample.payload.to_bytes())
        with self.lock:
            self.camera(sample.key_expr).status = status

    def _on_eos(self, sample) -> None:
        from gngdt.schemas.status import decode_stream_end

        end = decode_stream_end(sample.payload.to_bytes())
        with self.lock:
            self.camera(sample.key_expr).end = end

    def _on_topology(self, sample) -> None:
        stamp = FrameStamp.from_attachment(sample.attachment.to_bytes())
        latency_ms = (time.time_ns() - stamp.capture_time_ns) * 1e-6
        with self.lock:
            self.camera(sample.key_expr).received_latency_ms.append(latency_ms)

    def has_alive(self, *prefixes: str) -> bool:
        with self.lock:
            return all(any(key.startswith(prefix) for key in self.alive) for prefix in prefixes)

    def close(self) -> None:
        for entity in self._declared:
            entity.undeclare()
        self.session.close()


class BenchPipeline:
    """A ``gngdt router`` process and services started against it with ``transport``; every
    process is stopped by ``close()``."""

    def __init__(self, workdir: Path, transport: Transport, log_level: str = "INFO") -> None:
        workdir.mkdir(parents=True, exist_ok=True)
        self.workdir = workdir
        self.transport = transport
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        self.access = RunAccess(endpoint, workdir)
        shared = {"transport/shared_memory/enabled": transport.shared_memory}
        for client_file in self.access.client_files.values():
            client = json.loads(client_file.read_text())
            client.setdefault("transport", {})["shared_memory"] = {
                "enabled": transport.shared_memory}
            client_file.write_text(json.dumps(client, indent=2))
        router_file = workdir / "router.json5"
        router_file.write_text(settings_file_text({
            **router_settings([endpoint]), **shared,
            "transport/auth/usrpwd/dictionary_file": str(self.access.users_file)}))
        self.log_level = log_level
        self.children: list[Child] = []
        self.router = self._spawn("router", ["router", "--zenoh-config", str(router_file)])
        self.observer: Observer | None = None
        try:
            self.observer = Observer(self.access.client_file("log"))  # puts nothing
        except Exception:
            self.close()
            raise

    def start(self, command: str, arguments: list[str], label: str | None = None) -> Child:
        """``gngdt COMMAND ARGUMENTS`` as a client of the run; its output in ``LABEL.log``."""
        child = self._spawn(label or command, [
            command, *arguments, "--zenoh-config", str(self.access.client_file(command))])
        self.children.append(child)
        return child

    def _spawn(self, label: str, arguments: list[str]) -> Child:
        log_path = self.workdir / f"{label}.log"
        log_file = open(log_path, "wb")  # closed in close()
        process = subprocess.Popen(
            [sys.executable, "-m", "gngdt.services.cli", *arguments, "--log-level", self.log_level],
            cwd=REPO_ROOT, stdout=log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env={**lifecycle.child_environment(), **self.transport.environment},
            start_new_session=True)
        return Child(label, process, log_path, log_file)

    def failed(self) -> Child | None:
        """The first service that exited with an error."""
        return next((child for child in self.children
                     if child.process.poll() not in (None, 0)), None)

    def wait(self, condition, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            failed = self.failed()
            if failed is not None:
                raise RuntimeError(f"{failed.name} failed:\n{failed.stderr_tail()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"timed out waiting for {what}")
            time.sleep(0.05)

    def stream(self, captures: list[Child], cameras: list[str], wait_s: float = 60.0,
               exit_s: float = 120.0) -> CpuWindow:
        """Every process's CPU from the captures' liveliness tokens (declared after their
        start-up, just before their first frame) until they exit; then every service must end
        well (RuntimeError naming one that did not)."""
        window = CpuWindow(self.pids())
        self.wait(lambda: self.observer.has_alive(
            *(alive_key(camera, CAPTURE) for camera in cameras)), wait_s, "capture")
        window.start()
        while any(capture.process.poll() is None for capture in captures):
            window.sample()
            time.sleep(0.1)
        window.stop()
        for child in self.children:
            if child.process.wait(exit_s) != 0:
                raise RuntimeError(f"{child.name} failed:\n{child.stderr_tail()}")
        return window

    def pids(self) -> dict[str, int]:
        """Every process of the run by name (services by their log name, and the router)."""
        pids = {"router": self.router.process.pid}
        for child in self.children:
            pids[child.name] = child.process.pid
        return pids

    def close(self) -> None:
        if self.observer is not None:
            self.observer.close()
        for child in self.children:
            child.interrupt()
        for child in self.children:
            child.stop(30.0)
            child.stderr_file.close()
        self.router.interrupt()
        self.router.stop(20.0)
        self.router.stderr_file.close()


class CpuWindow:
    """CPU seconds of processes between ``start()`` and ``stop()``, as % of one core, and their
    peak RSS (VmHWM) while watched."""

    def __init__(self, pids: dict[str, int]) -> None:
        self.pids = pids
        self.peaks: dict[str, float] = {}
        self._start: dict[str, float] = {}
        self._end: dict[str, float] = {}
        self._started = self._stopped = 0.0

    def start(self) -> None:
        self._started = time.monotonic()
        self._start = {name: cpu_seconds(pid) for name, pid in self.pids.items()}

    def sample(self) -> None:
        """Remember each live process's CPU time (a process that has exited keeps its last)."""
        for name, pid in self.pids.items():
            seconds = cpu_seconds(pid)
            if seconds:
                self._end[name] = seconds
            self.peaks[name] = max(self.peaks.get(name, 0.0), status_mb(pid, "VmHWM"))

    def stop(self) -> None:
        self.sample()
        self._stopped = time.monotonic()

    @property
    def seconds(self) -> float:
        return self._stopped - self._started

    def percent(self) -> dict[str, float]:
        wall = max(self.seconds, 1e-9)
        return {name: 100.0 * (self._end.get(name, self._start[name]) - self._start[name]) / wall
                for name in self.pids}


#: what a publisher logs when it is undeclared (gngdt.services.plumbing.session)
_SHARED_LINE = re.compile(r"(gngdt/\S+): (\d+) of (\d+) large payloads went through shared memory")
_CLOUDS_LINE = re.compile(r"(\d+) of (\d+) clouds arrived through shared memory")


def shared_memory_use(log_text: str) -> dict[str, tuple[int, int]]:
    """``{topic or "clouds received": (through shared memory, of)}`` from a service's log."""
    use = {key: (int(shared), int(total))
           for key, shared, total in _SHARED_LINE.findall(log_text)}
    for shared, total in _CLOUDS_LINE.findall(log_text):
        use["clouds received"] = (int(shared), int(total))
    return use


def percentiles(values: list[float]) -> tuple[float, float]:
    """(p50, p99) of ``values``, NaN when there are none."""
    if not values:
        return float("nan"), float("nan")
    return float(np.percentile(values, 50)), float(np.percentile(values, 99))


def load_average() -> float:
    """The machine's 1-minute load average."""
    return os.getloadavg()[0]
