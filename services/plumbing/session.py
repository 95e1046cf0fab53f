"""Zenoh configuration and session opening shared by every service.

Secure defaults (DESIGN.md "Rendezvous"): services are zenoh *clients* of a router on
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


def _secure_defaults(config: zenoh.Config) -> None:
    _insert(config, _SECURE_DEFAULTS)


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
    """Configuration of a zenoh router listening on ``listen`` only, scouting off.

    ``listen`` None: the endpoints ``config_file`` lists, else `DEFAULT_ENDPOINT`. A file that
    asks for mutual TLS or access control makes a secure router, which never listens where a
    client could open a session without credentials (`anonymous_listeners`): ZenohSetupError.
    """
    import zenoh

    config = _load_config_file(config_file) if config_file is not None else zenoh.Config()
    config.insert_json5("mode", '"router"')
    if listen is None:
        listed = _setting(config, "listen/endpoints") if config_file is not None else None
        listen = listed if isinstance(listed, list) and listed else [DEFAULT_ENDPOINT]
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if config_file is None:
        config.insert_json5("connect/endpoints", "[]")
        _secure_defaults(config)
        # a client that stops reading is cut off after this long instead of zenoh's 5 s, during
        # which every message that must arrive (status, end of stream) would wait for it
        config.insert_json5("transport/link/tx/queue/congestion_control/block/wait_before_close",
                            str(BLOCKED_CLIENT_CUTOFF_US))
    anonymous = anonymous_listeners(config)
    if anonymous:
        raise ZenohSetupError(
            f"--zenoh-config {config_file} asks for authentication or access control, but a "
            f"client could open a session on {', '.join(anonymous)} without credentials (only "
            "tls/ and quic/ endpoints check certificates); listen on tls/ endpoints only, or "
            "add usrpwd authentication")
    return config


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
    endpoints = _setting(config, "listen/endpoints") or []
    return [str(endpoint) for endpoint in endpoints
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
                log.warning("no zenoh router at %s yet (%s); retrying for %.0f s more",
                            ", ".join(_endpoints(config)), _short(error), wait_s - waited)
            attempts += 1
            time.sleep(min(0.5, max(wait_s - waited, 0.0)))
            continue
        if attempts:
            log.info("connected to the zenoh router after %.1f s", time.monotonic() - started)
        return session


def _short(error: Exception) -> str:
    """zenoh's error text without the Rust source locations it appends."""
    return re.sub(r"\s*at \S+\.rs:\d+\.?", "", str(error)).strip()


def _open_failure(config: zenoh.Config, what: str, error: Exception) -> str:
    reason = _short(error)
    if _setting(config, "mode") == "router":
        listen = ", ".join(_setting(config, "listen/endpoints") or [])
        hint = ("another process (a router?) already listens there; pick a free port with "
                "--listen" if "in use" in reason else "check --listen and --zenoh-config")
        return f"cannot open a zenoh router on {listen}: {reason}; {hint}"
    endpoints = ", ".join(_endpoints(config)) or "no endpoint"
    return (f"cannot open zenoh {what} (router {endpoints}): {reason}; is a router running? "
            "start one with `gngdt router`")


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
                      latest_wins: bool) -> zenoh.Publisher:
    """The one place congestion is decided. ``latest_wins`` (images, clouds, topologies: a
    newer one supersedes it): ``DROP``, so that a consumer that does not keep up loses stale
    samples instead of stalling the publisher and everyone else. Otherwise (calibration, status,
    end of stream: what must arrive): ``BLOCK``, a consumer that stops reading altogether then
    being cut off by zenoh after ``transport/link/tx/queue/congestion_control/block/
    wait_before_close``."""
    import zenoh

    control = zenoh.CongestionControl.DROP if latest_wins else zenoh.CongestionControl.BLOCK
    return session.declare_publisher(key, encoding=encoding, congestion_control=control)


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
