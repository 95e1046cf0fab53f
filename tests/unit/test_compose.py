"""docker-compose.yml is validated here, since no Docker engine runs on our machines.

Every gngdt service's command must parse as a `gngdt` command line, every config file it names
must exist in the image (i.e. in this repository), and the router image must run the same zenoh
version as the eclipse-zenoh Python package.
"""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

import pytest
import yaml

from services.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
COMPOSE = yaml.safe_load((REPO / "docker-compose.yml").read_text())
SERVICES = COMPOSE["services"]
GNGDT_SERVICES = {name: spec for name, spec in SERVICES.items() if name != "router"}
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
    assert set(SERVICES) == {"router", "capture", "learner", "logger"}
    assert all(spec.get("build") == "." for spec in GNGDT_SERVICES.values())


@pytest.mark.parametrize("service", sorted(GNGDT_SERVICES))
def test_service_command_is_a_valid_gngdt_command_line(service):
    command = GNGDT_SERVICES[service]["command"]
    args = build_parser().parse_args(command)
    assert args.command == {"capture": "capture", "learner": "learn", "logger": "log"}[service]
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


def test_router_image_matches_the_zenoh_python_package():
    image, _, tag = SERVICES["router"]["image"].partition(":")
    assert image == "eclipse/zenoh"
    assert tag == version("eclipse-zenoh"), "pin the router image to the eclipse-zenoh package"


def test_router_listens_only_inside_the_compose_network():
    assert "ports" not in SERVICES["router"], "the router must not be published on the host"
    config = (REPO / "config/compose/zenoh-router.json5").read_text()
    assert "multicast: { enabled: false }" in config and "gossip: { enabled: false }" in config


def test_old_docker_compose_v1_accepts_the_top_level_keys():
    # docker-compose 1.x (still what many distributions ship) refuses any other top-level key,
    # e.g. `name:`; extension fields (x-...) are fine from file format 3.4
    v1_keys = {"version", "services", "networks", "volumes", "secrets", "configs"}
    assert {key for key in COMPOSE if not key.startswith("x-")} <= v1_keys
