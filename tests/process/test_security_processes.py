"""Security: loopback-only defaults without scouting, the TLS + access-control deployment of
``config/secure/`` on loopback, and checkpoint/parameter files that are validated, never
unpickled or evaluated."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from processes import bound_sockets, children, wait_for

from services.plumbing.session import (
    ZenohSetupError,
    client_config,
    free_tcp_port,
    open_config,
)

REPO_ROOT = Path(__file__).resolve().parents[2]
SECURE = REPO_ROOT / "config" / "secure"


@pytest.mark.timeout(90)
def test_running_router_and_learner_hold_only_loopback_listeners(
    free_port: int, spawn: Callable
) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port}"
    router = spawn("router", "--listen", endpoint)
    learner = spawn("learn", "--zenoh-connect", endpoint)
    probe = None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # wait until the learner's session is up
        try:
            probe = open_config(client_config([endpoint]))
        except ZenohSetupError:
            time.sleep(0.2)
            continue
        if list(probe.liveliness().get("gngdt/camera/learner/alive", timeout=1)):
            break
        time.sleep(0.2)
    else:
        raise AssertionError(Path(learner.log_path).read_text())
    probe.close()

    router_sockets = bound_sockets(router.pid)
    assert router_sockets == [("tcp", f"127.0.0.1:{free_port}", "listen")], router_sockets
    learner_sockets = bound_sockets(learner.pid)
    assert learner_sockets == [], learner_sockets  # a client: no listener, no scouting socket


def _descendants(pid: int) -> list[int]:
    found = []
    for child in children(pid):
        found += [child, *_descendants(child)]
    return found


@pytest.mark.timeout(150)
def test_every_listener_of_run_serve_and_its_services_is_on_loopback(
    tabletop_recording: Path, tmp_path: Path
) -> None:
    """`gngdt run --serve`: its router, learner, logger, capture and the rerun viewer server."""
    grpc_port, web_port = free_tcp_port(), free_tcp_port()
    log_path = tmp_path / "run.log"
    with open(log_path, "wb") as output:
        run = subprocess.Popen(
            [sys.executable, "-m", "services.cli", "run", str(tabletop_recording), "--serve",
             "--rate", "0.01", "--grpc-port", str(grpc_port), "--web-port", str(web_port)],
            cwd=REPO_ROOT, stdout=output, stderr=output, start_new_session=True)
    try:
        wait_for(lambda: "replaying" in log_path.read_text(), 90, "every service to be up")
        processes = [run.pid, *_descendants(run.pid)]
        assert len(processes) >= 5, log_path.read_text()  # run, 3 services, the rerun server
        found = {pid: bound_sockets(pid) for pid in processes}
    finally:
        run.send_signal(signal.SIGINT)
        run.wait(60)
    listeners = [address for sockets in found.values() for protocol, address, state in sockets
                 if state == "listen"]
    assert f"127.0.0.1:{grpc_port}" in listeners and f"127.0.0.1:{web_port}" in listeners
    for pid, sockets in found.items():
        for protocol, address, state in sockets:
            assert protocol == "tcp" and state == "listen", (pid, sockets)  # no UDP: no scouting
            assert address.startswith("127.0.0.1:"), (pid, sockets)


# ------------------------------------------------------------------ TLS + access control
@pytest.fixture(scope="module")
def certificates(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """CA, router and client certificates made by ``config/secure/make-certs.sh``: one allowed
    service (``gngdt-service``) and one signed by the same CA but not in the ACL."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make test certificates")
    directory = tmp_path_factory.mktemp("certs")
    subprocess.run(["sh", str(SECURE / "make-certs.sh"), str(directory), "localhost",
                    "gngdt-service", "intruder"], check=True, capture_output=True, timeout=60)
    return directory


def _with_certificates(source: Path, certificates: Path, target: Path) -> Path:
    """A copy of a shipped config whose certificate paths point at ``certificates``."""
    text = source.read_text()
    assert "config/secure/certs/" in text
    target.write_text(text.replace("config/secure/certs/", f"{certificates}/"))
    return target


def _client(config_file: Path, endpoint: str, *, name: str | None = "gngdt-service",
            certificates: Path | None = None):
    config = client_config([endpoint], config_file)
    config.insert_json5("connect/timeout_ms", "3000")
    if name is None:  # the client has the CA but no certificate of its own
        config.insert_json5("transport/link/tls/connect_certificate", "null")
        config.insert_json5("transport/link/tls/connect_private_key", "null")
    elif name != "gngdt-service":
        config.insert_json5("transport/link/tls/connect_certificate",
                            json.dumps(f"{certificates}/{name}.pem"))
        config.insert_json5("transport/link/tls/connect_private_key",
                            json.dumps(f"{certificates}/{name}.key"))
    return open_config(config)


@pytest.mark.timeout(120)
def test_tls_router_with_access_control_admits_only_certified_services(
    certificates: Path, free_port: int, spawn: Callable, tmp_path: Path
) -> None:
    import zenoh

    router_file = _with_certificates(SECURE / "router.json5", certificates,
                                     tmp_path / "router.json5")
    client_file = _with_certificates(SECURE / "client.json5", certificates,
                                     tmp_path / "client.json5")
    endpoint = f"tls/127.0.0.1:{free_port}"
    router = spawn("router", "--listen", endpoint, "--zenoh-config", str(router_file))
    deadline = time.monotonic() + 30
    while "listening on" not in Path(router.log_path).read_text():
        assert time.monotonic() < deadline and router.poll() is None, \
            Path(router.log_path).read_text()
        time.sleep(0.1)

    # no client certificate: the mutual-TLS handshake fails, no session at all
    with pytest.raises(ZenohSetupError):
        _client(client_file, endpoint, name=None)
    # plain TCP to the TLS port: no session either
    plain = client_config([endpoint.replace("tls/", "tcp/")])
    plain.insert_json5("connect/timeout_ms", "3000")
    with pytest.raises(ZenohSetupError):
        open_config(plain)

    publisher = _client(client_file, endpoint)
    listener = _client(client_file, endpoint)
    intruder = _client(client_file, endpoint, name="intruder", certificates=certificates)
    received: dict[str, list[bytes]] = {"service": [], "intruder": []}
    subscribers = [
        listener.declare_subscriber("gngdt/**", lambda s: received["service"].append(
            s.payload.to_bytes())),
        intruder.declare_subscriber("gngdt/**", lambda s: received["intruder"].append(
            s.payload.to_bytes())),
    ]
    intruder_put_seen: list[bytes] = []
    subscribers.append(listener.declare_subscriber(
        "gngdt/camera/eos", lambda s: intruder_put_seen.append(s.payload.to_bytes())))
    try:
        time.sleep(0.5)
        deadline = time.monotonic() + 10
        while len(received["service"]) < 5 and time.monotonic() < deadline:
            publisher.put("gngdt/camera/points", b"cloud",
                          congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.05)
        for _ in range(10):  # the intruder may not publish into the pipeline either
            intruder.put("gngdt/camera/eos", b"forged end of stream")
            time.sleep(0.05)
        time.sleep(0.5)
    finally:
        for subscriber in subscribers:
            subscriber.undeclare()
        for session in (publisher, listener, intruder):
            session.close()
    assert len(received["service"]) >= 5 and set(received["service"]) == {b"cloud"}
    assert b"cloud" not in received["intruder"]  # (its own puts are delivered to it locally)
    assert intruder_put_seen == []


