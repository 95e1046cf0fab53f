"""Zenoh configuration and session opening shared by every service.

Secure defaults (DESIGN.md "Rendezvous"): services are zenoh *clients* of a router on
``tcp/127.0.0.1:7447``; they listen nowhere and multicast/gossip scouting is off, so nothing is
exposed beyond loopback. ``--zenoh-config FILE.json5`` replaces these defaults entirely (remote
routers, TLS, access control); ``--zenoh-connect ENDPOINT`` only changes where to connect.
"""

from __future__ import annotations

import argparse
import json
import logging
import socket
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


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


def _secure_defaults(config: zenoh.Config) -> None:
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")


def client_config(
    connect: list[str] | None = None, config_file: Path | None = None
) -> zenoh.Config:
    """Configuration of a service session.

    With ``config_file`` the file is used as is (only ``connect`` endpoints, when given, are set).
    Otherwise: client mode, connect to ``connect`` (default the loopback router), listen nowhere,
    scouting off.
    """
    import zenoh

    if config_file is not None:
        config = _load_config_file(config_file)
        if connect:
            config.insert_json5("connect/endpoints", json.dumps(list(connect)))
        return config
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps(list(connect or [DEFAULT_ENDPOINT])))
    config.insert_json5("listen/endpoints", "[]")
    _secure_defaults(config)
    return config


def router_config(listen: list[str], config_file: Path | None = None) -> zenoh.Config:
    """Configuration of a zenoh router listening on ``listen`` only, scouting off."""
    import zenoh

    config = _load_config_file(config_file) if config_file is not None else zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if config_file is None:
        config.insert_json5("connect/endpoints", "[]")
        _secure_defaults(config)
    return config


def _load_config_file(path: Path) -> zenoh.Config:
    import zenoh

    if not Path(path).is_file():
        raise ZenohSetupError(f"--zenoh-config: {path}: no such file")
    try:
        return zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ZenohSetupError(f"--zenoh-config: {path}: {error}") from error


def open_config(config: zenoh.Config, what: str = "session") -> zenoh.Session:
    """Open a session, turning zenoh's connection failure into a clear ``ZenohSetupError``."""
    import zenoh

    try:
        return zenoh.open(config)
    except zenoh.ZError as error:
        endpoints: Any = _endpoints(config)
        raise ZenohSetupError(
            f"cannot open zenoh {what} (endpoints {endpoints}): {error}; "
            "is a router running? start one with `gngdt router`"
        ) from error


def _endpoints(config: zenoh.Config) -> Any:
    try:
        return json.loads(config.get_json("connect/endpoints"))
    except Exception:  # only used to word an error message
        return "?"


def open_session(args: argparse.Namespace) -> zenoh.Session:
    """Open the process's one zenoh session from the parsed ``--zenoh-*`` options."""
    connect = getattr(args, "zenoh_connect", None)
    config = client_config(connect, getattr(args, "zenoh_config", None))
    return open_config(config)


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def wait_for_subscribers(publisher: zenoh.Publisher, timeout_s: float) -> bool:
    """Wait until a subscriber matches ``publisher``; False when ``timeout_s`` ran out."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if publisher.matching_status.matching:
            return True
        time.sleep(0.01)
    return bool(publisher.matching_status.matching)
