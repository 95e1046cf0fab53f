"""Run a zenoh router for standalone services (zenoh's own router, through the Python binding)."""

from __future__ import annotations

import argparse
import json
import logging

from services.plumbing import lifecycle
from services.plumbing.session import (
    DEFAULT_ENDPOINT,
    ZenohSetupError,
    open_config,
    router_config,
)

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt router                                   # listens on tcp/127.0.0.1:7447
  gngdt router --listen tcp/127.0.0.1:7450
  gngdt router --zenoh-config config/secure/router.json5   # TLS, roles: the file's endpoints
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on (repeatable; default: the --zenoh-config file's listen "
        f"endpoints, else {DEFAULT_ENDPOINT}); a router with mutual TLS or access control "
        "refuses any endpoint where a client needs no credentials",
    )
    parser.add_argument(
        "--zenoh-config",
        metavar="FILE.json5",
        help="zenoh configuration file (mode and listen endpoints are set by this command)",
    )


def main(args: argparse.Namespace) -> int:
    try:
        config = router_config(args.listen, args.zenoh_config)
        listen = json.loads(config.get_json("listen/endpoints"))
        session = open_config(config, what="router")
    except ZenohSetupError as error:
        log.error("%s", error)
        return 1
    try:
        with lifecycle.graceful() as stop:
            print(f"zenoh router listening on {', '.join(listen)} (Ctrl-C to stop)", flush=True)
            while not stop.wait(0.5):  # with a timeout: a signal zenoh's threads received
                pass                       # runs its Python handler only when we wake up
    finally:
        session.close()
    log.info("router stopped (%s)", lifecycle.stop_reason())
    return 0
