"""Packaging: what a wheel or the Docker image of gngdt really contains."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    """The wheel `pip wheel .` builds from this checkout (offline: no build isolation)."""
    # from a clean copy: setuptools reuses a checkout's build/ folder, stale files and all
    source = tmp_path_factory.mktemp("source") / "gngdt"
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "*.egg-info", "__pycache__", "recordings", "runs", "out",
        "report", ".hypothesis", ".*_cache"))
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "--no-index", "-q", "-w", str(out), str(source)],
                   check=True, capture_output=True, timeout=300)
    (path,) = out.glob("gngdt-*.whl")
    with zipfile.ZipFile(path) as archive:
        yield archive


def test_the_wheel_ships_config_and_every_module(wheel: zipfile.ZipFile) -> None:
    names = set(wheel.namelist())
    for path in (REPO / "config").rglob("*"):
        if path.is_file() and path.suffix in (".toml", ".json5"):
            assert f"gngdt_config/{path.relative_to(REPO / 'config')}" in names, path
    for package in ("gngdt_core", "schemas", "services"):
        for path in (REPO / package).rglob("*.py"):
            assert str(path.relative_to(REPO)) in names, f"{path} is not in the wheel"


def test_the_licence_is_an_spdx_expression(wheel: zipfile.ZipFile) -> None:
    assert isinstance(PYPROJECT["project"]["license"], str)  # a table is deprecated
    (metadata,) = [name for name in wheel.namelist() if name.endswith(".dist-info/METADATA")]
    text = wheel.read(metadata).decode()
    assert "License-Expression: BSD-3-Clause" in text
    assert any(name.endswith("licenses/LICENSE") for name in wheel.namelist())


