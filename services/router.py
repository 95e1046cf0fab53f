"""Run a zenoh router for standalone services (zenoh's own router, through the Python binding)."""

from __future__ import annotations

import argparse
import logging

from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.session import (
    DEFAULT_ENDPOINT,
    open_config,
    router_config,
    router_endpoints,
)

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt router                                   # listens on tcp/127.0.0.1:7447
  gngdt router --listen tcp/127.0.0.1:7450
  gngdt router --zenoh-config config/secure/router.json5   # TLS, roles: the file's endpoints
  gngdt router --zenoh-config config/hosts/router-b.json5  # listen, link to host A's router
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
        help="zenoh configuration file, e.g. one written for zenohd: its listen endpoints "
        "(unless --listen), connect endpoints (links to other routers) and the rest are used; "
        "the mode is set to router. A file without listen endpoints listens on "
        f"{DEFAULT_ENDPOINT} only, never on every interface",
    )


def main(args: argparse.Namespace) -> int:
    config = router_config(args.listen, args.zenoh_config)
    session = open_config(config, what="router")  # ZenohSetupError: said by the command line
    listen = router_endpoints(config)
    links = router_endpoints(config, "connect/endpoints")
    try:
        with lifecycle.graceful() as stop:
            print(f"zenoh router listening on {', '.join(listen) or 'no endpoint'}"
                  + (f", linking to {', '.join(links)}" if links else "")
                  + " (Ctrl-C to stop)", flush=True)
            while not stop.wait(0.5):  # with a timeout: a signal zenoh's threads received
                pass                       # runs its Python handler only when we wake up
    finally:
        session.close()
    log.info("router stopped (%s)", lifecycle.stop_reason())
    return 0
