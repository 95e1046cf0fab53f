"""docker-compose.yml is validated here, since no Docker engine runs on our machines.

Every gngdt service's command must parse as a `gngdt` command line, every config file it names
must exist in the image (i.e. in this repository), and the router images must run the same zenoh
version as the eclipse-zenoh Python package. The `two-hosts` profile keeps its hosts apart: only
the routers meet, router B links to router A, each service reaches its own host's router.
"""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

import pytest
import yaml

from gngdt.services.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
COMPOSE = yaml.safe_load((REPO / "docker-compose.yml").read_text())
SERVICES = COMPOSE["services"]
ROUTERS = {name: spec for name, spec in SERVICES.items()
           if spec.get("image", "").startswith("eclipse/zenoh:")}
GNGDT_SERVICES = {name: spec for name, spec in SERVICES.items() if name not in ROUTERS}
#: what a plain `docker compose up` starts (services of no profile)
DEFAULT_SERVICES = {name for name, spec in SERVICES.items() if not spec.get("profiles")}
TWO_HOSTS = {name for name, spec in SERVICES.items() if "two-hosts" in spec.get("profiles", [])}
#: where the Dockerfile puts the repository inside the image
IMAGE_APP_DIR = "/app/"


def _host_path(container_path: str, volumes: list[str]) -> Path | None:
    """The repository file a container path refers to, through /app or a bind mount."""
    if container_path.startswith(IMAGE_APP_DIR):
        return REPO / container_path.removeprefix(IMAGE_APP_DIR)
    for volume in volumes:
        source, target, *_ = volume.split(":")
        if container_path.startswith(target.rstrip("/") + "/"):
            return REPO / source / container_path.removeprefix(target.rstrip("/") + "/")
    return None


def test_compose_runs_router_and_the_three_services():
    assert DEFAULT_SERVICES == {"router", "capture", "learner", "logger"}
    assert TWO_HOSTS == {"router-a", "router-b", "capture-a", "learner-b", "logger-b"}
    assert set(SERVICES) == DEFAULT_SERVICES | TWO_HOSTS
    assert all(spec.get("build") == "." for spec in GNGDT_SERVICES.values())


@pytest.mark.parametrize("service", sorted(GNGDT_SERVICES))
def test_service_command_is_a_valid_gngdt_command_line(service):
    command = GNGDT_SERVICES[service]["command"]
    args = build_parser().parse_args(command)
    role = service.removesuffix("-a").removesuffix("-b")
    assert args.command == {"capture": "capture", "learner": "learn", "logger": "log"}[role]
    assert args.zenoh_config is not None, "in compose every service must reach the router by name"


@pytest.mark.parametrize("service", sorted(SERVICES))
def test_every_config_file_named_exists(service):
    spec = SERVICES[service]
    volumes = spec.get("volumes", [])
    named = [arg for arg in spec["command"] if arg.endswith((".json5", ".toml"))]
    assert named, f"{service} names no config file"
    for container_path in named:
        host_path = _host_path(container_path, volumes)
        assert host_path is not None, f"{service}: {container_path} is neither in /app nor mounted"
        assert host_path.is_file(), f"{service}: {container_path} -> {host_path} does not exist"


def test_replayed_recording_is_bundled():
    capture = GNGDT_SERVICES["capture"]
    recording = _host_path(capture["command"][1], capture["volumes"])
    assert recording is not None and recording.is_file()


@pytest.mark.parametrize("router", sorted(ROUTERS))
def test_router_image_matches_the_zenoh_python_package(router):
    image, _, tag = ROUTERS[router]["image"].partition(":")
    assert image == "eclipse/zenoh"
    assert tag == version("eclipse-zenoh"), "pin the router image to the eclipse-zenoh package"


@pytest.mark.parametrize("router", sorted(ROUTERS))
def test_router_listens_only_inside_the_compose_network(router):
    spec = ROUTERS[router]
    assert "ports" not in spec, "the router must not be published on the host"
    config = _host_path(spec["command"][1], spec["volumes"]).read_text()
    assert "multicast: { enabled: false }" in config and "gossip: { enabled: false }" in config


def _zenoh_config(service: str):
    import zenoh

    spec = SERVICES[service]
    path = next(arg for arg in spec["command"] if arg.endswith(".json5"))
    return zenoh.Config.from_file(str(_host_path(path, spec.get("volumes", []))))


def _setting(config, key: str):
    import json

    return json.loads(config.get_json(key))


def test_two_hosts_meet_only_through_their_routers():
    networks = {name: set(SERVICES[name].get("networks", ["default"])) for name in TWO_HOSTS}
    assert networks["router-a"] & networks["router-b"] == {"link"}
    for service in ("capture-a",):
        assert networks[service] == {"host-a"}
    for service in ("learner-b", "logger-b"):
        assert networks[service] == {"host-b"}
    assert "link" not in set().union(*(networks[name] for name in TWO_HOSTS - set(ROUTERS)))
    # each service is a client of its own host's router, which it shares a network with
    for service in TWO_HOSTS - set(ROUTERS):
        config = _zenoh_config(service)
        host = service.rsplit("-", 1)[1]
        assert _setting(config, "mode") == "client"
        assert _setting(config, "connect/endpoints") == [f"tcp/router-{host}:7447"]
        assert networks[f"router-{host}"] & networks[service]
    # router B links to router A on `link`; router A links nowhere
    assert _setting(_zenoh_config("router-b"), "connect/endpoints") == ["tcp/router-a:7447"]
    assert _setting(_zenoh_config("router-a"), "connect/endpoints") in ([], {})
    for router in ("router-a", "router-b"):
        assert _setting(_zenoh_config(router), "listen/endpoints") == ["tcp/0.0.0.0:7447"]


def test_two_hosts_write_apart_from_the_one_host_run():
    outputs = [arg for name in ("learner", "logger", "learner-b", "logger-b")
               for arg in SERVICES[name]["command"] if arg.startswith("/out/")]
    assert len(outputs) == len(set(outputs)) == 4


def test_old_docker_compose_v1_accepts_the_top_level_keys():
    # docker-compose 1.x (still what many distributions ship) refuses any other top-level key,
    # e.g. `name:`; extension fields (x-...) are fine from file format 3.4
    v1_keys = {"version", "services", "networks", "volumes", "secrets", "configs"}
    assert {key for key in COMPOSE if not key.startswith("x-")} <= v1_keys
