"""Zenoh configuration: secure defaults, pass-through files, router rendezvous on loopback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gngdt.services.plumbing.session import (
    ZenohSetupError,
    client_config,
    free_tcp_port,
    open_config,
)

REPO_ROOT = Path(__file__).resolve().parents[2]


def test_unreachable_router_is_a_clear_error(free_port: int) -> None:
    with pytest.raises(ZenohSetupError, match="gngdt router"):
        open_config(client_config([f"tcp/127.0.0.1:{free_port}"]))


def test_clients_meet_through_the_router(router_endpoint: str) -> None:
    import zenoh

    publisher_session = open_config(client_config([router_endpoint]))
    subscriber_session = open_config(client_config([router_endpoint]))
    received: list[bytes] = []
    subscriber = subscriber_session.declare_subscriber(
        "gngdt/test/x", lambda sample: received.append(sample.payload.to_bytes()))
    publisher = publisher_session.declare_publisher(
        "gngdt/test/x", congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + 5
    while not received and time.monotonic() < deadline:
        publisher.put(b"hello")
        time.sleep(0.05)
    subscriber.undeclare()
    publisher_session.close()
    subscriber_session.close()
    assert received and received[0] == b"hello"


@pytest.mark.timeout(60)
def test_gngdt_router_process_serves_clients(free_port: int) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port}"
    process = subprocess.Popen(
        [sys.executable, "-m", "gngdt.services.cli", "router", "--listen", endpoint],
        cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
    )
    try:
        assert "listening on" in process.stdout.readline().decode()
        session = open_config(client_config([endpoint]))
        session.close()
        process.send_signal(signal.SIGINT)
        assert process.wait(20) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()




@pytest.mark.timeout(60)
def test_gngdt_router_listens_where_its_config_file_says(tmp_path: Path, spawn) -> None:
    from helpers.processes import bound_sockets, log_text, wait_for

    port = free_tcp_port()
    path = tmp_path / "zenohd.json5"
    path.write_text(f'{{ mode: "router", listen: {{ endpoints: ["tcp/127.0.0.1:{port}"] }},\n'
                    "  scouting: { multicast: { enabled: false } } }\n")
    router = spawn("router", "--zenoh-config", str(path))
    wait_for(lambda: "listening on" in log_text(router), 30, "the router's start")
    assert f"listening on tcp/127.0.0.1:{port}" in log_text(router)
    listeners = [address for protocol, address, state in bound_sockets(router.pid)
                 if state == "listen"]
    assert listeners == [f"127.0.0.1:{port}"]  # the file's endpoint only, not 7447
    session = open_config(client_config([f"tcp/127.0.0.1:{port}"]))
    session.close()
