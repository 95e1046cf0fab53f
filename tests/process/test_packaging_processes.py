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
        ".git", ".venv*", "build", "*.egg-info", "__pycache__", "recordings", "runs", "out",
        "report", ".hypothesis", ".*_cache"))
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "--no-index", "-q", "-w", str(out), str(source)],
                   check=True, capture_output=True, timeout=300)
    (path,) = out.glob("gngdt-*.whl")
    with zipfile.ZipFile(path) as archive:
        yield archive


#: repository folder -> where its modules land in the wheel (pyproject.toml's package-dir)
WHEEL_FOLDERS = {"gngdt": "gngdt", "gngdt_core": "gngdt/core", "schemas": "gngdt/schemas",
                 "gngdt_io": "gngdt/io", "gngdt_eval": "gngdt/eval", "services": "gngdt/services",
                 "config": "gngdt/config"}


def test_the_wheel_ships_config_and_every_module(wheel: zipfile.ZipFile) -> None:
    names = set(wheel.namelist())
    for path in (REPO / "config").rglob("*"):
        if path.is_file() and path.suffix in (".toml", ".json5"):
            assert f"gngdt/config/{path.relative_to(REPO / 'config')}" in names, path
    for folder, inside in WHEEL_FOLDERS.items():
        for path in (REPO / folder).rglob("*.py"):
            shipped = f"{inside}/{path.relative_to(REPO / folder)}"
            assert shipped in names, f"{path} is not in the wheel"


def test_the_wheel_installs_one_top_level_name(wheel: zipfile.ZipFile,
                                               tmp_path: Path) -> None:
    """Installed into a fresh venv, the wheel adds `gngdt` (and its metadata) to site-packages and
    nothing generic such as `services` or `schemas`; the namespace imports from there."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=120)
    python = venv / "bin" / "python"
    purelib = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    site = Path(subprocess.run([str(python), "-c", purelib], check=True, capture_output=True,
                               text=True).stdout.strip())
    with zipfile.ZipFile(wheel.filename) as archive:  # unpacked as pip installs a pure wheel
        archive.extractall(site)
    top = sorted({name.split("/")[0] for name in wheel.namelist()})
    assert [name for name in top if not name.endswith(".dist-info")] == ["gngdt"]
    assert sorted(path.name for path in site.iterdir() if not path.name.startswith("_")) == top
    # (no dependencies in this venv: the config package imports none)
    shown = subprocess.run([str(python), "-I", "-c", "import gngdt.config; "
                            "print(*gngdt.config.__path__)"], check=True, capture_output=True,
                           text=True, timeout=60, cwd=tmp_path).stdout
    assert shown.startswith(str(site / "gngdt" / "config")), shown


def test_the_licence_is_an_spdx_expression(wheel: zipfile.ZipFile) -> None:
    assert isinstance(PYPROJECT["project"]["license"], str)  # a table is deprecated
    (metadata,) = [name for name in wheel.namelist() if name.endswith(".dist-info/METADATA")]
    text = wheel.read(metadata).decode()
    assert "License-Expression: BSD-3-Clause" in text
    assert any(name.endswith("licenses/LICENSE") for name in wheel.namelist())


