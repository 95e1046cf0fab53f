"""Zenoh configuration: secure defaults, pass-through files, router rendezvous on loopback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gngdt.services.plumbing.environment import (
    PARENT_ENV,
    SHARED_MEMORY_POOL_ENV,
    read_environment,
)
from gngdt.services.plumbing.session import (
    DEFAULT_ENDPOINT,
    ZenohSetupError,
    client_config,
    router_config,
    router_endpoints,
)

REPO_ROOT = Path(__file__).resolve().parents[2]


def setting(config, key: str):
    return json.loads(config.get_json(key))


def test_default_client_config_is_loopback_only_without_scouting() -> None:
    config = client_config()
    assert setting(config, "mode") == "client"
    assert setting(config, "connect/endpoints") == [DEFAULT_ENDPOINT]
    assert setting(config, "listen/endpoints") == []
    assert setting(config, "scouting/multicast/enabled") is False
    assert setting(config, "scouting/gossip/enabled") is False


def test_router_config_listens_where_told_only() -> None:
    config = router_config(["tcp/127.0.0.1:7999"])
    assert setting(config, "mode") == "router"
    assert setting(config, "listen/endpoints") == ["tcp/127.0.0.1:7999"]
    assert setting(config, "scouting/multicast/enabled") is False


def test_router_config_without_anything_listens_on_loopback_and_links_nowhere() -> None:
    config = router_config(None)
    assert router_endpoints(config) == [DEFAULT_ENDPOINT]
    assert setting(config, "connect/endpoints") == []


def test_router_config_file_listen_and_connect_are_honoured(tmp_path: Path) -> None:
    path = tmp_path / "zenohd.json5"
    path.write_text('{ mode: "router", listen: { endpoints: ["tcp/10.9.0.2:7447"] },\n'
                    '  connect: { endpoints: ["tcp/10.9.0.1:7447"] } }\n')
    config = router_config(None, path)
    assert router_endpoints(config) == ["tcp/10.9.0.2:7447"]
    assert router_endpoints(config, "connect/endpoints") == ["tcp/10.9.0.1:7447"]
    # --listen wins over the file; the file's links stay
    config = router_config(["tcp/127.0.0.1:7450"], path)
    assert router_endpoints(config) == ["tcp/127.0.0.1:7450"]
    assert router_endpoints(config, "connect/endpoints") == ["tcp/10.9.0.1:7447"]


def test_router_config_file_per_mode_listen_is_honoured(tmp_path: Path) -> None:
    path = tmp_path / "per_mode.json5"
    path.write_text('{ listen: { endpoints: { router: ["tcp/127.0.0.1:7461"], '
                    'peer: ["tcp/127.0.0.1:0"] } } }')
    assert router_endpoints(router_config(None, path)) == ["tcp/127.0.0.1:7461"]


def test_router_config_file_without_listen_stays_on_loopback_and_says_so(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "no_listen.json5"
    path.write_text('{ connect: { endpoints: ["tcp/10.9.0.1:7447"] } }')
    with caplog.at_level("WARNING"):
        config = router_config(None, path)
    # zenoh's own default would be tcp/[::]:7447, every interface
    assert router_endpoints(config) == [DEFAULT_ENDPOINT]
    assert router_endpoints(config, "connect/endpoints") == ["tcp/10.9.0.1:7447"]
    assert "sets no listen endpoints" in caplog.text and DEFAULT_ENDPOINT in caplog.text


def test_config_file_passes_through(tmp_path: Path) -> None:
    path = tmp_path / "site.json5"
    path.write_text('{ mode: "peer", connect: { endpoints: ["tcp/10.1.2.3:7447"] },\n'
                    "  // a comment, as json5 allows\n"
                    '  scouting: { multicast: { enabled: false } } }\n')
    config = client_config(config_file=path)
    assert setting(config, "mode") == "peer"
    assert setting(config, "connect/endpoints") == ["tcp/10.1.2.3:7447"]
    overridden = client_config(["tcp/127.0.0.1:1234"], config_file=path)
    assert setting(overridden, "connect/endpoints") == ["tcp/127.0.0.1:1234"]


def test_missing_or_bad_config_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ZenohSetupError, match="no such file"):
        client_config(config_file=tmp_path / "absent.json5")
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ")
    with pytest.raises(ZenohSetupError, match=r"bad\.json5"):
        client_config(config_file=bad)


@pytest.mark.parametrize("path", sorted((REPO_ROOT / "config").rglob("*.json5")),
                         ids=lambda path: str(path.relative_to(REPO_ROOT / "config")))
def test_every_shipped_config_keeps_gngdt_bounds(path: Path) -> None:
    import json

    import zenoh

    from gngdt.services.plumbing.session import BLOCKED_CLIENT_CUTOFF_US, MAX_MESSAGE_BYTES

    config = zenoh.Config.from_file(str(path))
    rx = json.loads(config.get_json("transport/link/rx"))
    assert rx["max_message_size"] == MAX_MESSAGE_BYTES
    if json.loads(config.get_json("mode")) == "router" or "router" in path.name:
        block = json.loads(config.get_json("transport/link/tx/queue/congestion_control/block"))
        assert block["wait_before_close"] == BLOCKED_CLIENT_CUTOFF_US


@pytest.mark.parametrize(("value", "expected"), [
    ("", None), ("0", 0), ("2.5", int(2.5 * 1024 * 1024)), ("64", 64 * 1024 * 1024)])
def test_shared_memory_pool_setting(value: str, expected: int | None) -> None:
    environment = read_environment({SHARED_MEMORY_POOL_ENV: value})
    assert environment.shm_pool_bytes == expected and not environment.problems


@pytest.mark.parametrize("value", ["lots", "-1", "nan", "inf", "1e308", "1025"])
def test_a_wrong_shared_memory_pool_setting_is_named_and_ignored(value: str) -> None:
    """inf and 1e308 once killed every service with OverflowError (int(inf * 2**20))."""
    environment = read_environment({SHARED_MEMORY_POOL_ENV: value})
    assert environment.shm_pool_bytes is None
    assert len(environment.problems) == 1
    assert SHARED_MEMORY_POOL_ENV in environment.problems[0]
    assert repr(value) in environment.problems[0]


@pytest.mark.parametrize("value", ["abc", "0", "-5", "1e9", "99999999999"])
def test_a_wrong_parent_pid_is_named_and_ignored(value: str) -> None:
    environment = read_environment({PARENT_ENV: value})
    assert environment.parent_pid is None and PARENT_ENV in environment.problems[0]
