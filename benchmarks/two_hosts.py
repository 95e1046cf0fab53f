"""Two "hosts" on one Linux machine for tests: two network namespaces joined by a veth pair,
each with a private /dev/shm (so zenoh shared memory cannot cross from one to the other, as it
cannot between real machines), processes started inside them, the link cut and restored, and
everything removed afterwards (needs root; ``unavailable()`` says why not).

    host A: 10.99.0.1/24 on veth ``ga<id>``  <---->  host B: 10.99.0.2/24 on veth ``gb<id>``

Each host is held by an *anchor* process (``sleep``) living in the host's network namespace and
in a mount namespace of its own with a tmpfs on /dev/shm; every process of the host is started
with ``nsenter -t ANCHOR -m -n``. Names carry this process's id, so concurrent runs do not meet,
and leftovers of a run that was killed outright are removed by the next one.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from gngdt.schemas.wire import DEFAULT_CAMERA, LEARNER, LOGGER_ALIVE, alive_key

REPO_ROOT = Path(__file__).resolve().parents[1]
PREFIX = "gngdt-"
ADDRESSES = {"A": "10.99.0.1", "B": "10.99.0.2"}


def _run(*command: str) -> subprocess.CompletedProcess:
    return subprocess.run(command, capture_output=True, text=True, timeout=30)


def unavailable() -> str | None:
    """Why two hosts cannot be made here, or None."""
    if not sys.platform.startswith("linux"):
        return "network namespaces are Linux only"
    if os.geteuid() != 0:
        return "network namespaces need root (CAP_SYS_ADMIN, CAP_NET_ADMIN)"
    missing = [tool for tool in ("ip", "unshare", "nsenter") if shutil.which(tool) is None]
    if missing:
        return f"missing {', '.join(missing)}"
    probe = f"{PREFIX}probe-{os.getpid()}"
    made = _run("ip", "netns", "add", probe)
    _run("ip", "netns", "del", probe)
    if made.returncode != 0:
        return f"`ip netns add` fails here: {made.stderr.strip()}"
    return None


def remove_leftovers() -> None:
    """Namespaces of earlier runs whose process is gone (killed before it could clean up)."""
    for line in _run("ip", "netns", "list").stdout.splitlines():
        name = line.split()[0] if line.split() else ""
        if not name.startswith(PREFIX):
            continue
        owner = name.rsplit("-", 1)[-1]
        if owner.isdigit() and not Path(f"/proc/{owner}").exists():
            _run("ip", "netns", "del", name)


class Host:
    """One network namespace with a private /dev/shm, and the processes started in it."""

    def __init__(self, name: str, label: str, log_dir: Path) -> None:
        self.name = name  # of the network namespace
        self.label = label  # "A" or "B"
        self.address = ADDRESSES[label]
        self.log_dir = log_dir
        self.processes: list[subprocess.Popen] = []
        self.anchor: subprocess.Popen | None = None

    def hold(self) -> None:
        """Start the anchor: the namespace's process with its own /dev/shm."""
        self.anchor = subprocess.Popen(
            ["ip", "netns", "exec", self.name, "unshare", "-m", "--propagation", "private",
             "sh", "-c", "mount -t tmpfs -o size=256m tmpfs /dev/shm && exec sleep infinity"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if self.anchor.poll() is not None:
                raise RuntimeError(f"host {self.label}: {self.anchor.stderr.read().decode()}")
            comm = Path(f"/proc/{self.anchor.pid}/comm")
            if comm.exists() and comm.read_text().strip() == "sleep":
                return
            time.sleep(0.02)
        raise RuntimeError(f"host {self.label}: its anchor did not start")

    def start(self, name: str, *command: str) -> subprocess.Popen:
        """``command`` on this host (cwd: the repository; output to ``<log_dir>/<name>.log``)."""
        log_path = self.log_dir / f"{name}.log"
        with open(log_path, "ab") as log_file:
            process = subprocess.Popen(
                ["nsenter", "-t", str(self.anchor.pid), "-m", "-n", "--", *command],
                cwd=REPO_ROOT, stdout=log_file, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, start_new_session=True)
        process.log_path = log_path  # type: ignore[attr-defined]
        self.processes.append(process)
        return process

    def gngdt(self, name: str, *arguments: str) -> subprocess.Popen:
        """``gngdt ARGUMENTS`` on this host."""
        return self.start(name, sys.executable, "-m", "gngdt.services.cli", *arguments)

    def run(self, *command: str, timeout_s: float = 60) -> subprocess.CompletedProcess:
        """``command`` on this host, to its end."""
        return subprocess.run(["nsenter", "-t", str(self.anchor.pid), "-m", "-n", "--",
                               *command], cwd=REPO_ROOT, capture_output=True, text=True,
                              timeout=timeout_s)

    def shm_device(self) -> str:
        """The device of this host's /dev/shm (private hosts have different ones)."""
        return self.run("stat", "-c", "%d", "/dev/shm/.").stdout.strip()

    def stop_processes(self) -> None:
        """Stop every process started on the host (SIGINT, then SIGKILL)."""
        for process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for process in self.processes:
            stop(process)
        self.processes = []

    def close(self) -> None:
        """Stop every process of the host, then its anchor."""
        self.stop_processes()
        if self.anchor is not None and self.anchor.poll() is None:
            self.anchor.kill()
            self.anchor.wait()


def stop(process: subprocess.Popen, timeout_s: float = 20.0) -> int:
    """Wait for ``process`` (SIGINT it first if it runs), killing it after ``timeout_s``."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        return process.wait(timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        return process.wait()


class TwoHosts:
    """Hosts A and B joined by a veth pair; ``close()`` removes everything, whatever happened."""

    def __init__(self, log_dir: Path) -> None:
        owner = os.getpid()
        self.a = Host(f"{PREFIX}A-{owner}", "A", log_dir)
        self.b = Host(f"{PREFIX}B-{owner}", "B", log_dir)
        short = owner % 10**6
        self.veth = {"A": f"ga{short}", "B": f"gb{short}"}

    def __enter__(self) -> TwoHosts:
        remove_leftovers()
        try:
            for host in (self.a, self.b):
                self._check(_run("ip", "netns", "add", host.name))
            self._check(_run("ip", "link", "add", self.veth["A"], "type", "veth", "peer", "name",
                             self.veth["B"]))
            for host in (self.a, self.b):
                veth = self.veth[host.label]
                self._check(_run("ip", "link", "set", veth, "netns", host.name))
                self._check(_run("ip", "-n", host.name, "addr", "add", f"{host.address}/24",
                                 "dev", veth))
                self._check(_run("ip", "-n", host.name, "link", "set", "lo", "up"))
                self._check(_run("ip", "-n", host.name, "link", "set", veth, "up"))
                host.hold()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @staticmethod
    def _check(result: subprocess.CompletedProcess) -> None:
        if result.returncode != 0:
            raise RuntimeError(f"{' '.join(result.args)}: {result.stderr.strip()}")

    def link(self, up: bool) -> None:
        """Bring host A's end of the link up or down."""
        self._check(_run("ip", "-n", self.a.name, "link", "set", self.veth["A"],
                         "up" if up else "down"))

    def close(self) -> None:
        for host in (self.b, self.a):
            host.close()
        for host in (self.a, self.b):
            _run("ip", "netns", "del", host.name)
        _run("ip", "link", "del", self.veth["A"])  # only there if the move failed

    @staticmethod
    def left_behind() -> list[str]:
        """Namespaces of this process still present (none after ``close()``)."""
        lines = _run("ip", "netns", "list").stdout.splitlines()
        return [line.split()[0] for line in lines
                if line.startswith(PREFIX) and line.split()[0].endswith(f"-{os.getpid()}")]


#: where each host's services reach its router (its own loopback, as on one host)
LOCAL_ROUTER = "tcp/127.0.0.1:7447"
#: the example configurations of a two-host deployment, and the address of host A in them
HOST_CONFIGS = REPO_ROOT / "config" / "hosts"
EXAMPLE_ADDRESS_A = "192.168.1.10"


def endpoint(host: Host) -> str:
    """Where the services of ``host`` reach their router."""
    return LOCAL_ROUTER


class Deployment:
    """gngdt on two hosts: a ``gngdt router`` on each, B's linked to A's by its configuration
    file (config/hosts/, as zenohd reads it), capture on A, the learner and the logger where asked,
    and a watcher (``zenoh_probe.py watch``) on B reporting topologies and liveliness."""

    def __init__(self, hosts: TwoHosts, workdir: Path, recording: Path,
                 capture_options: tuple[str, ...] = (), learner_on: str = "B",
                 logger_on: str | None = "B", learner_options: tuple[str, ...] = ()) -> None:
        self.hosts = hosts
        self.workdir = workdir
        self.recording = recording
        self.capture_options = capture_options
        self.learner_on, self.logger_on = learner_on, logger_on
        self.learner_options = learner_options
        self.watch_path = workdir / "watch.jsonl"
        self.rrd_path = workdir / "two-hosts.rrd"
        self.routers: dict[str, subprocess.Popen] = {}
        self.services: dict[str, subprocess.Popen] = {}

    def host(self, label: str) -> Host:
        return self.hosts.a if label == "A" else self.hosts.b

    def router_file(self, label: str) -> Path:
        """Host ``label``'s router configuration: the shipped example (config/hosts/), with host
        A's address in it. A listens on loopback and its address; B on loopback, linked to A."""
        text = (HOST_CONFIGS / f"router-{label.lower()}.json5").read_text()
        path = self.workdir / f"router-{label}.json5"
        path.write_text(text.replace(EXAMPLE_ADDRESS_A, self.hosts.a.address))
        return path

    def start_router(self, label: str) -> subprocess.Popen:
        router = self.host(label).gngdt(f"router-{label}", "router", "--zenoh-config",
                                        str(self.router_file(label)))
        self.routers[label] = router
        return router

    def service(self, name: str, label: str, *arguments: str) -> subprocess.Popen:
        process = self.host(label).gngdt(name, *arguments, "--zenoh-connect",
                                         endpoint(self.host(label)))
        self.services[name] = process
        return process

    def start(self, timeout_s: float = 180.0) -> None:
        """Routers, watcher, learner and logger; once they are alive, capture."""
        for label in ("A", "B"):
            self.start_router(label)
        self.probe("B", "watch", self.watch_path)
        self.service("learner", self.learner_on, "learn", *self.learner_options)
        expected = [alive_key(DEFAULT_CAMERA, LEARNER)]
        if self.logger_on is not None:
            self.service("logger", self.logger_on, "log", "--save", str(self.rrd_path),
                         "--keep-running")
            expected.append(LOGGER_ALIVE)
        self.wait(lambda: all(self.alive(key) for key in expected), timeout_s,
                  "the learner and the logger")
        self.service("capture", "A", "capture", str(self.recording), "--loop",
                     *self.capture_options)

    def wait(self, condition, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            for name, process in {**self.services, **self.routers}.items():
                if process.poll() is not None and process.returncode != 0:
                    raise RuntimeError(f"{name} exited {process.returncode}:\n"
                                       + Path(process.log_path).read_text(errors="replace"))
            if time.monotonic() > deadline:
                raise TimeoutError(f"timed out waiting for {what}")
            time.sleep(0.05)

    def probe(self, label: str, mode: str, out: Path) -> subprocess.Popen:
        """``zenoh_probe.py MODE`` on host ``label`` (a client of its router), writing ``out``."""
        return self.host(label).start(f"{mode}-{label}", sys.executable, str(
            Path(__file__).with_name("zenoh_probe.py")), mode, endpoint(self.host(label)),
            str(out))

    def records(self, event: str = "topology") -> list[dict]:
        import json

        if not self.watch_path.exists():
            return []
        lines = self.watch_path.read_text().splitlines()
        records = []
        for line in lines:
            try:
                record = json.loads(line)
            except ValueError:  # a line being written
                continue
            if record["ev"] == event:
                records.append(record)
        return records

    def alive(self, prefix: str) -> bool:
        """Whether the watcher last saw a liveliness token under ``prefix`` appear."""
        events = sorted(self.records("alive") + self.records("gone"), key=lambda r: r["t"])
        state: dict[str, bool] = {}
        for record in events:
            state[record["key"]] = record["ev"] == "alive"
        return any(alive for key, alive in state.items() if key.startswith(prefix))

    def topologies_captured_after(self, time_ns: int) -> list[dict]:
        return [record for record in self.records() if record["capture_ns"] > time_ns]

    def kill_router(self, label: str) -> None:
        router = self.routers.pop(label)
        os.killpg(router.pid, signal.SIGKILL)
        router.wait()

    def query(self, label: str, key: str = "gngdt/camera/topology") -> dict:
        """A late joiner's ``get`` from a fresh client on host ``label``."""
        import json

        result = self.host(label).run(sys.executable, str(Path(__file__).with_name(
            "zenoh_probe.py")), "query", endpoint(self.host(label)), key)
        if result.returncode != 0:
            raise RuntimeError(result.stderr)
        return json.loads(result.stdout.strip().splitlines()[-1])

    def stop_services(self) -> dict[str, int]:
        """SIGINT capture, then learner and logger; their exit codes."""
        codes = {}
        for name in ("capture", "learner", "logger"):
            if name in self.services:
                codes[name] = stop(self.services[name], 60.0)
        return codes


def link_bytes(hosts: TwoHosts) -> tuple[int, int]:
    """Bytes host A has sent to B and received from B over the link so far (its veth's
    counters: zenoh's payloads, headers and TCP/IP included)."""
    folder = f"/sys/class/net/{hosts.veth['A']}/statistics"
    result = hosts.a.run("cat", f"{folder}/tx_bytes", f"{folder}/rx_bytes")
    sent, received = (int(value) for value in result.stdout.split())
    return sent, received
