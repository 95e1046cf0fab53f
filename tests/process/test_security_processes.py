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
from helpers.processes import bound_sockets, children, wait_for

from gngdt.services.plumbing.session import (
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
            [sys.executable, "-m", "gngdt.services.cli", "run", str(tabletop_recording), "--serve",
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
ROLES = ("capture", "learner", "logger", "viewer")


@pytest.fixture(scope="module")
def certificates(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """CA, router and client certificates made by ``config/secure/make-certs.sh``: one per role
    and one signed by the same CA but in no role (``intruder``)."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make test certificates")
    directory = tmp_path_factory.mktemp("certs")
    subprocess.run(["sh", str(SECURE / "make-certs.sh"), str(directory), "localhost",
                    *(f"gngdt-{role}" for role in ROLES), "intruder"],
                   check=True, capture_output=True, timeout=60)
    return directory


def _with_certificates(source: Path, certificates: Path, target: Path) -> Path:
    """A copy of a shipped config whose certificate paths point at ``certificates``."""
    text = source.read_text()
    assert "config/secure/certs/" in text
    target.write_text(text.replace("config/secure/certs/", f"{certificates}/"))
    return target


def _client(certificates: Path, endpoint: str, role: str | None, tmp_path: Path,
            certificate: str | None = None):
    """A session with ``role``'s shipped client file (``certificate``: another certificate's
    name in it; None role: the CA but no certificate of its own)."""
    config_file = _with_certificates(SECURE / "client-capture.json5", certificates,
                                     tmp_path / f"client-{role}.json5")
    config = client_config([endpoint], config_file)
    config.insert_json5("connect/timeout_ms", "3000")
    name = certificate or (f"gngdt-{role}" if role else None)
    for key, suffix in (("connect_certificate", "pem"), ("connect_private_key", "key")):
        value = None if name is None else f"{certificates}/{name}.{suffix}"
        config.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    return open_config(config)


@pytest.mark.timeout(120)
def test_a_secure_router_refuses_a_plain_tcp_listener(certificates: Path, free_port: int,
                                                      spawn: Callable, tmp_path: Path) -> None:
    router_file = _with_certificates(SECURE / "router.json5", certificates,
                                     tmp_path / "router.json5")
    router = spawn("router", "--listen", f"tcp/127.0.0.1:{free_port}", "--zenoh-config",
                   str(router_file))
    assert router.wait(60) == 1
    text = Path(router.log_path).read_text()
    assert "without credentials" in text and "Traceback" not in text


@pytest.mark.timeout(120)
def test_tls_router_with_access_control_keeps_each_role_to_its_streams(
    certificates: Path, free_port: int, spawn: Callable, tmp_path: Path
) -> None:
    import zenoh

    text = _with_certificates(SECURE / "router.json5", certificates, tmp_path / "r.json5")
    endpoint = f"tls/127.0.0.1:{free_port}"
    router_file = tmp_path / "router.json5"
    router_file.write_text(text.read_text().replace("tls/127.0.0.1:7447", endpoint))
    router = spawn("router", "--zenoh-config", str(router_file))  # the file's endpoint
    deadline = time.monotonic() + 30
    while "listening on" not in Path(router.log_path).read_text():
        assert time.monotonic() < deadline and router.poll() is None, \
            Path(router.log_path).read_text()
        time.sleep(0.1)
    assert bound_sockets(router.pid) == [("tcp", f"127.0.0.1:{free_port}", "listen")]

    # no client certificate: the mutual-TLS handshake fails, no session at all
    with pytest.raises(ZenohSetupError):
        _client(certificates, endpoint, None, tmp_path)
    # plain TCP to the TLS port: no session either
    plain = client_config([endpoint.replace("tls/", "tcp/")])
    plain.insert_json5("connect/timeout_ms", "3000")
    with pytest.raises(ZenohSetupError):
        open_config(plain)

    sessions = {role: _client(certificates, endpoint, role, tmp_path) for role in ROLES}
    sessions["intruder"] = _client(certificates, endpoint, "intruder", tmp_path, "intruder")
    heard: dict[str, list[tuple[str, bytes]]] = {name: [] for name in sessions}
    subscribers = [session.declare_subscriber("gngdt/**", lambda sample, name=name: heard[
        name].append((str(sample.key_expr), sample.payload.to_bytes())))
        for name, session in sessions.items()]
    forgeries = [("logger", "gngdt/camera/eos"), ("viewer", "gngdt/camera/eos"),
                 ("learner", "gngdt/camera/eos"), ("capture", "gngdt/camera/objects"),
                 ("logger", "gngdt/camera/objects"), ("intruder", "gngdt/camera/points")]
    try:
        time.sleep(0.5)
        deadline = time.monotonic() + 10
        while len(heard["learner"]) < 5 and time.monotonic() < deadline:
            sessions["capture"].put("gngdt/camera/points", b"cloud",
                                    congestion_control=zenoh.CongestionControl.BLOCK)
            sessions["learner"].put("gngdt/camera/objects", b"objects",
                                    congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.05)
        for name, key in forgeries:
            for _ in range(5):
                sessions[name].put(key, f"forged by {name}".encode())
        time.sleep(1.0)
    finally:
        for subscriber in subscribers:
            subscriber.undeclare()
        for session in sessions.values():
            session.close()
    for role in ROLES:  # each hears the capture and the learner, and no forgery
        received = heard[role]
        assert ("gngdt/camera/points", b"cloud") in received, role
        assert ("gngdt/camera/objects", b"objects") in received, role
        foreign = [item for item in received if item[1].startswith(b"forged")
                   and item[1] != f"forged by {role}".encode()]  # its own puts stay local
        assert foreign == [], (role, foreign)
    assert all(payload.startswith(b"forged by intruder") for _, payload in heard["intruder"])
