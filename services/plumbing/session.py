"""Zenoh configuration and session opening shared by every service.

Secure defaults (docs/contracts.md "Rendezvous"): services are zenoh *clients* of a router on
``tcp/127.0.0.1:7447``; they listen nowhere and multicast/gossip scouting is off, so nothing is
exposed beyond loopback. ``--zenoh-config FILE.json5`` replaces these defaults entirely (remote
routers, TLS, access control); ``--zenoh-connect ENDPOINT`` only changes where to connect.

A service started before its router waits for it (``--router-wait``, retrying and saying so), as
ROS 2 nodes wait for rmw_zenohd; once connected, zenoh reconnects by itself after a router
restart, retrying every ``RECONNECT_PERIOD_MS`` at most. Messages larger than
``MAX_MESSAGE_BYTES`` are dropped by zenoh on receipt (routers and services alike). zenoh's own
log goes to stderr at the level ``RUST_LOG`` names (default: errors only).
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import socket
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt.services.plumbing.environment import SHARED_MEMORY_POOL_ENV

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
#: how long a service waits for its router at start by default
DEFAULT_ROUTER_WAIT_S = 30.0
#: the largest zenoh message accepted (larger ones are dropped on receipt): above every
#: legitimate gngdt message (a 2,000,000-point cloud, the learner's limit, is 30 MB; a 4K
#: colour image 25 MB), far below what would threaten a process's memory
MAX_MESSAGE_BYTES = 32 * 1024 * 1024
#: the longest pause between two attempts to reach a lost router
RECONNECT_PERIOD_MS = 1000
#: how long a router waits on a client that reads nothing before cutting it off, microseconds
BLOCKED_CLIENT_CUTOFF_US = 1_000_000


class ZenohSetupError(RuntimeError):
    """The zenoh configuration is invalid or the router cannot be reached."""


def add_zenoh_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--zenoh-config`` and ``--zenoh-connect`` to a service's parser."""
    group = parser.add_argument_group("zenoh")
    group.add_argument(
        "--zenoh-config",
        type=Path,
        metavar="FILE.json5",
        help="zenoh configuration file used as is (routers, TLS, access control); "
        "default: client of tcp/127.0.0.1:7447, no listener, scouting off",
    )
    group.add_argument(
        "--zenoh-connect",
        action="append",
        metavar="ENDPOINT",
        help=f"router endpoint to connect to (repeatable; default {DEFAULT_ENDPOINT})",
    )
    group.add_argument(
        "--router-wait",
        type=float,
        default=DEFAULT_ROUTER_WAIT_S,
        metavar="SECONDS",
        help="at start, how long to wait for the router, retrying twice a second "
        f"(default {DEFAULT_ROUTER_WAIT_S:g}; 0: fail at once)",
    )


#: settings of every default session: no scouting, no oversized message
_SECURE_DEFAULTS: dict[str, Any] = {
    "scouting/multicast/enabled": False,
    "scouting/gossip/enabled": False,
    "transport/link/rx/max_message_size": MAX_MESSAGE_BYTES,
    # 16 batches (1 MB) of data in flight per link instead of 2: a reader that is only late (a
    # loaded machine) loses no image or cloud; one that never reads is cut off or dropped
    "transport/link/tx/queue/size/data": 16,
}
#: a publisher waits this long for room in its own queue (toward the router) before it drops a
#: latest-wins sample, microseconds (zenoh: 1 ms, and 50 ms for a fragmented message): the
#: router, not a consumer, is on the other end, so waiting only absorbs scheduling delays
_PUBLISHER_DROP_WAITS: dict[str, Any] = {
    "transport/link/tx/queue/congestion_control/drop/wait_before_drop": 100_000,
    "transport/link/tx/queue/congestion_control/drop/max_wait_before_drop_fragments": 1_000_000,
}


def _insert(config: zenoh.Config, settings: dict[str, Any]) -> None:
    for key, value in settings.items():
        config.insert_json5(key, json.dumps(value))


def client_settings(connect: list[str] | None = None) -> dict[str, Any]:
    """A default service session's settings (zenoh key path -> value): client of ``connect``
    (default the loopback router), listening nowhere, scouting off."""
    return {
        "mode": "client",
        "connect/endpoints": list(connect or [DEFAULT_ENDPOINT]),
        "connect/retry": {"period_init_ms": 100, "period_max_ms": RECONNECT_PERIOD_MS,
                          "period_increase_factor": 2},
        "listen/endpoints": [],
        **_SECURE_DEFAULTS,
        **_PUBLISHER_DROP_WAITS,
    }


def client_config(
    connect: list[str] | None = None, config_file: Path | None = None
) -> zenoh.Config:
    """Configuration of a service session.

    With ``config_file`` the file is used as is (only ``connect`` endpoints, when given, are set).
    Otherwise :func:`client_settings`.
    """
    import zenoh

    if config_file is not None:
        config = _load_config_file(config_file)
        if connect:
            config.insert_json5("connect/endpoints", json.dumps(list(connect)))
        return config
    config = zenoh.Config()
    _insert(config, client_settings(connect))
    return config


def router_config(listen: list[str] | None, config_file: Path | None = None) -> zenoh.Config:
    """Configuration of a zenoh router, scouting off.

    Where it listens: ``listen`` when given (``--listen`` wins); else the file's own
    ``listen/endpoints``; else the loopback default ``DEFAULT_ENDPOINT`` -- never zenoh's own
    default, every interface (a file that sets no listen endpoints opens nothing more than
    loopback). A file's ``connect/endpoints`` (links to other routers) are kept. A file that
    asks for mutual TLS or access control makes a secure router, which never listens where a
    client could open a session without credentials (`anonymous_listeners`): ZenohSetupError.
    """
    import zenoh

    config = _load_config_file(config_file) if config_file is not None else zenoh.Config()
    config.insert_json5("mode", '"router"')
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    elif config_file is None or not listen_endpoints_set(config):
        if config_file is not None:
            log.warning("%s sets no listen endpoints: listening on %s only (loopback); set "
                        "listen.endpoints in the file or --listen to listen elsewhere",
                        config_file, DEFAULT_ENDPOINT)
        config.insert_json5("listen/endpoints", json.dumps([DEFAULT_ENDPOINT]))
    if config_file is None:
        _insert(config, {key: value for key, value in router_settings([]).items()
                         if key not in ("mode", "listen/endpoints")})
    anonymous = anonymous_listeners(config)
    if anonymous:
        raise ZenohSetupError(
            f"--zenoh-config {config_file} asks for authentication or access control, but a "
            f"client could open a session on {', '.join(anonymous)} without credentials (only "
            "tls/ and quic/ endpoints check certificates); listen on tls/ endpoints only, or "
            "add usrpwd authentication")
    return config


def router_settings(listen: list[str]) -> dict[str, Any]:
    """A default router's settings (zenoh key path -> value): listening on ``listen`` only,
    linking to no other router, scouting off, gngdt's bounds."""
    return {
        "mode": "router",
        "listen/endpoints": list(listen),
        "connect/endpoints": [],
        **_SECURE_DEFAULTS,
        # a client that stops reading is cut off after this long instead of zenoh's 5 s, during
        # which every message that must arrive (status, end of stream) would wait for it
        "transport/link/tx/queue/congestion_control/block/wait_before_close":
            BLOCKED_CLIENT_CUTOFF_US,
    }


def settings_file_text(settings: dict[str, Any]) -> str:
    """Settings by key path (``"transport/auth/usrpwd/user"``) as the text of a zenoh
    configuration file (JSON, which JSON5 reads), for ``--zenoh-config``."""
    nested: dict[str, Any] = {}
    for key, value in settings.items():
        *parents, leaf = key.split("/")
        branch = nested
        for name in parents:
            branch = branch.setdefault(name, {})
        branch[leaf] = value
    return json.dumps(nested, indent=2)


def listen_endpoints_set(config: zenoh.Config) -> bool:
    """Whether ``config`` sets its own ``listen/endpoints`` (zenoh's default, left unset, is
    every interface: ``{"router": ["tcp/[::]:7447"], ...}``)."""
    import zenoh

    return config.get_json("listen/endpoints") != zenoh.Config().get_json("listen/endpoints")


def router_endpoints(config: zenoh.Config, key: str = "listen/endpoints") -> list[str]:
    """The endpoints a router opened with ``config`` listens on (``key`` "listen/endpoints") or
    connects to ("connect/endpoints"): a list, or the ``router`` entry of a per-mode mapping."""
    value = _setting(config, key) or []
    if isinstance(value, dict):
        value = value.get("router", [])
    return [str(endpoint) for endpoint in value]


def anonymous_listeners(config: zenoh.Config) -> list[str]:
    """The listen endpoints of a secure router (mutual TLS or access control configured) on
    which a client needs no credentials: every endpoint but tls/ and quic/ ones under mutual
    TLS, every endpoint without any authentication; none with usrpwd (it covers every link) or
    on a router that asks for neither (gngdt's loopback default)."""
    mutual_tls = _setting(config, "transport/link/tls/enable_mtls") is True
    access_control = _setting(config, "access_control/enabled") is True
    if not (mutual_tls or access_control) or _setting(
            config, "transport/auth/usrpwd/dictionary_file"):
        return []
    return [endpoint for endpoint in router_endpoints(config)
            if not (mutual_tls and str(endpoint).split("/", 1)[0] in ("tls", "quic"))]


def _load_config_file(path: Path) -> zenoh.Config:
    import zenoh

    if not Path(path).is_file():
        raise ZenohSetupError(f"--zenoh-config: {path}: no such file")
    try:
        return zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ZenohSetupError(f"--zenoh-config: {path}: {error}") from error


def init_zenoh_logging() -> None:
    """Route zenoh's own log to stderr at ``RUST_LOG``'s level, errors only by default (as
    zenoh's examples do); once per process."""
    import zenoh

    global _zenoh_logging
    if not _zenoh_logging:
        zenoh.init_log_from_env_or("error")
        _zenoh_logging = True


_zenoh_logging = False


def open_config(config: zenoh.Config, what: str = "session",
                wait_s: float = 0.0) -> zenoh.Session:
    """Open a session, turning zenoh's failure into a clear ``ZenohSetupError``.

    ``wait_s``: keep retrying (logged) this long while no router answers.
    """
    import zenoh

    init_zenoh_logging()
    started = time.monotonic()
    attempts = 0
    while True:
        try:
            session = zenoh.open(config)
        except zenoh.ZError as error:
            waited = time.monotonic() - started
            if waited >= wait_s:
                raise ZenohSetupError(_open_failure(config, what, error)) from error
            if attempts % 20 == 0:  # the first failure, then every ten seconds
                log.warning("no zenoh router at %s yet (%s); retrying for %.0f s more (%s)",
                            ", ".join(_endpoints(config)), _short(error), wait_s - waited,
                            router_advice(what))
            attempts += 1
            time.sleep(min(0.5, max(wait_s - waited, 0.0)))
            continue
        if attempts:
            log.info("connected to the zenoh router after %.1f s", time.monotonic() - started)
        return session


def _short(error: Exception | str) -> str:
    """zenoh's error text without the Rust source locations it appends."""
    return re.sub(r"\s*at \S+\.rs:\d+\.?", "", str(error)).strip()


def _open_failure(config: zenoh.Config, what: str, error: Exception) -> str:
    reason = _short(error)
    if _setting(config, "mode") == "router":
        listen = ", ".join(router_endpoints(config)) or "no endpoint"
        hint = ("another process (a router?) already listens there; pick a free port with "
                "--listen" if "in use" in reason else "check --listen and --zenoh-config")
        return f"cannot open a zenoh router on {listen}: {reason}; {hint}"
    endpoints = ", ".join(_endpoints(config)) or "no endpoint"
    return f"cannot open zenoh {what} (router {endpoints}): {reason}; {router_advice(what)}"


#: the session that joins ROS 2's router (`gngdt ros2 --ros2-connect`, `gngdt run --ros2`)
ROS2_SESSION = "ROS 2 session"


def router_advice(what: str = "session") -> str:
    """What to start when no router answers, as docs/ros2.md says: ROS 2's own router for the
    ROS 2 side (rmw_zenohd holds port 7447: a `gngdt router` there would take its place), a
    `gngdt router` otherwise."""
    if what == ROS2_SESSION:
        return ("is ROS 2's router running there? start it first, `ros2 run rmw_zenoh_cpp "
                "rmw_zenohd` (it listens on tcp/[::]:7447), or name the endpoint it listens on; "
                "`gngdt router` is not ROS 2's router (docs/ros2.md)")
    return ("is a router running? start one with `gngdt router`; beside ROS 2, rmw_zenohd is "
            "the router (it holds 7447: connect to it, do not start `gngdt router` there; "
            "docs/ros2.md)")


def endpoint_listening(endpoint: str, timeout_s: float = 2.0) -> bool | None:
    """Whether something accepts TCP connections at a ``tcp/HOST:PORT`` endpoint (None: another
    kind of endpoint, which this cannot tell)."""
    kind, _, address = endpoint.partition("/")
    host, _, port = address.rpartition(":")
    if kind != "tcp" or not port.isdigit() or not host:
        return None
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
            return True
    except OSError:
        return False


def _setting(config: zenoh.Config, key: str) -> Any:
    try:
        return json.loads(config.get_json(key))
    except Exception:  # only used to word messages
        return None


def _endpoints(config: zenoh.Config) -> list[str]:
    return [str(endpoint) for endpoint in _setting(config, "connect/endpoints") or []]


def open_session(args: argparse.Namespace) -> zenoh.Session:
    """Open the process's one zenoh session from the parsed ``--zenoh-*`` options, waiting up
    to ``--router-wait`` seconds for the router."""
    connect = getattr(args, "zenoh_connect", None)
    config = client_config(connect, getattr(args, "zenoh_config", None))
    wait_s = getattr(args, "router_wait", 0.0)
    if wait_s < 0:
        raise ZenohSetupError(f"--router-wait must be >= 0, got {wait_s}")
    return open_config(config, wait_s=wait_s)


def declare_publisher(session: zenoh.Session, key: str, encoding: str,
                      latest_wins: bool, *, large: bool | None = None,
                      pool_bytes: int | None = None) -> SharedMemoryPublisher:
    """The one place congestion and transport are decided. ``latest_wins`` (images, clouds,
    topologies: a newer one supersedes it): ``DROP``, so that a consumer that does not keep up
    loses stale samples instead of stalling the publisher and everyone else; large payloads go
    through zenoh shared memory when the link allows (:class:`SharedMemoryPublisher`).
    Otherwise (calibration, status, end of stream: what must arrive): ``BLOCK``, a consumer that
    stops reading altogether then being cut off by zenoh after ``transport/link/tx/queue/
    congestion_control/block/wait_before_close``. ``large`` (default: ``latest_wins``): its
    payloads are large, and go through shared memory too (a capture's clouds paced by the
    learner: every one must arrive). ``pool_bytes``: the shared-memory pool's size
    (``GNGDT_SHM_POOL_MB``, `gngdt.services.plumbing.environment`; None: from the payloads)."""
    import zenoh

    control = zenoh.CongestionControl.DROP if latest_wins else zenoh.CongestionControl.BLOCK
    publisher = session.declare_publisher(key, encoding=encoding, congestion_control=control)
    return SharedMemoryPublisher(session, publisher,
                                 shared_memory=latest_wins if large is None else large,
                                 pool_bytes=pool_bytes)


#: payloads at least this large go through gngdt's shared-memory pool when the link allows
#: (below it, zenoh's own transport optimisation decides: it copies payloads of 3 kB and more
#: into its own 16 MiB pool)
SHARED_MEMORY_MIN_BYTES = 64 * 1024
#: a publisher's pool holds this many of its largest payload: the one being written, the one a
#: learner holds while it learns, those in flight in the router and toward slow subscribers
SHARED_MEMORY_POOL_PAYLOADS = 8
#: the smallest pool a publisher makes, bytes
SHARED_MEMORY_MIN_POOL_BYTES = 4 * 1024 * 1024
#: and the largest (unless GNGDT_SHM_POOL_MB says): eight 4K colour images would take 200 MB
#: and a 4K stream's three pools 570 MB of a ROS 2 bridge's 1.5 GB peak under a flood; beyond
#: the pool, payloads go over the network
SHARED_MEMORY_MAX_POOL_BYTES = 64 * 1024 * 1024
#: what a process lacking shared memory needs (mlock of its pool, room in /dev/shm)
_SHARED_MEMORY_HINT = ("raise its locked-memory limit (ulimit -l; Docker: --ulimit memlock=-1 or "
                       "cap_add IPC_LOCK) and give /dev/shm room (Docker: --shm-size or ipc: host)")


class SharedMemoryPublisher:
    """A zenoh publisher whose large payloads travel through zenoh shared memory when the
    session's link to its router negotiated it, and over the network otherwise.

    zenoh negotiates shared memory per link: both ends on one host, with shared memory enabled
    (``transport/shared_memory/enabled``, zenoh's default; ``false`` in the session's and the
    router's configuration turns it off). A payload of ``SHARED_MEMORY_MIN_BYTES`` or more is
    then copied once into this publisher's pool (``ShmProvider``, made at the first such payload
    with room for ``SHARED_MEMORY_POOL_PAYLOADS`` of it, at most ``SHARED_MEMORY_MAX_POOL_BYTES``)
    and only a reference crosses the router
    to subscribers on the same host; zenoh turns it back into bytes on any link that has no
    shared memory (another host). When the pool cannot be made (locked-memory limit, a small
    /dev/shm) or is full (subscribers still hold its payloads), the payload goes over the
    network as it would without shared memory: said once in the log, counted. ``pool_bytes``:
    the pool's size instead (0: no pool).
    """

    def __init__(self, session: zenoh.Session, publisher: zenoh.Publisher,
                 shared_memory: bool = True, pool_bytes: int | None = None) -> None:
        self._session = session
        self._publisher = publisher
        self._pool_bytes = pool_bytes
        self._shared_memory = shared_memory and self._pool_bytes != 0
        self._provider: Any = None
        self._unavailable = False  # the pool could not be made: the network from now on
        self._pool_full_said = False
        self._no_link_said = False
        #: large payloads sent through shared memory / over the network
        self.sent_shared = 0
        self.sent_network = 0

    @property
    def key_expr(self) -> zenoh.KeyExpr:
        return self._publisher.key_expr

    @property
    def matching_status(self) -> zenoh.MatchingStatus:
        return self._publisher.matching_status

    def put(self, payload: bytes | bytearray, attachment: bytes | None = None) -> None:
        self._publisher.put(self._payload(payload), attachment=attachment)

    def _payload(self, payload: bytes | bytearray) -> Any:
        """``payload`` as it is, or copied into a shared-memory buffer."""
        if not self._shared_memory or len(payload) < SHARED_MEMORY_MIN_BYTES:
            return payload
        buffer = None
        if self._link_shares_memory():
            buffer = self._allocate(len(payload))
        elif not self._no_link_said:
            self._no_link_said = True
            log.info("%s: no shared memory on the link to the router (another host, or shared "
                     "memory off); large payloads go over the network", self.key_expr)
        if buffer is None:
            self.sent_network += 1
            return payload
        buffer[:] = payload  # the one copy: zenoh's buffers take bytes only, no memoryview
        self.sent_shared += 1
        return buffer

    def _link_shares_memory(self) -> bool:
        return any(getattr(transport, "is_shm", False)
                   for transport in self._session.info.transports())

    def _allocate(self, size: int) -> Any:
        """A shared-memory buffer of ``size`` bytes, or None (no pool, or the pool is full)."""
        if self._unavailable:
            return None
        import zenoh

        try:
            import zenoh.shm as shm

            if self._provider is None:
                pool = self._pool_bytes or min(max(SHARED_MEMORY_MIN_POOL_BYTES,
                                                   SHARED_MEMORY_POOL_PAYLOADS * size),
                                               max(SHARED_MEMORY_MAX_POOL_BYTES, size))
                self._provider = shm.ShmProvider.default_backend(pool)
                log.debug("%s: shared-memory pool of %.1f MB", self.key_expr, pool / 1e6)
            # collect what subscribers released, compact, else give up: never block a publisher
            return self._provider.alloc(size, policy=shm.GarbageCollect(shm.Defragment()))
        except (ImportError, zenoh.ZError) as error:
            if self._provider is None:
                self._unavailable = True
                log.warning("%s: no shared memory (%s); large payloads go over the network. "
                            "For shared memory, %s", self.key_expr, _short(str(error)),
                            _SHARED_MEMORY_HINT)
            elif not self._pool_full_said:
                self._pool_full_said = True
                log.info("%s: shared-memory pool full or too small for %d bytes (%s); such "
                         "payloads go over the network (%s sizes the pool)", self.key_expr,
                         size, _short(str(error)), SHARED_MEMORY_POOL_ENV)
            return None

    def undeclare(self) -> None:
        if self.sent_shared or self.sent_network:
            log.info("%s: %d of %d large payloads went through shared memory", self.key_expr,
                     self.sent_shared, self.sent_shared + self.sent_network)
        self._publisher.undeclare()


def through_shared_memory(sample: zenoh.Sample) -> bool:
    """Whether ``sample``'s payload arrived through shared memory (diagnostics)."""
    as_shm = getattr(sample.payload, "as_shm", None)
    return as_shm is not None and as_shm() is not None


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def wait_for_subscribers(publisher: zenoh.Publisher, timeout_s: float,
                         stop: threading.Event | None = None) -> bool:
    """Wait until a subscriber matches ``publisher``; False when ``timeout_s`` ran out (or
    ``stop`` was set)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not (stop is not None and stop.is_set()):
        if publisher.matching_status.matching:
            return True
        time.sleep(0.01)
    return bool(publisher.matching_status.matching)
