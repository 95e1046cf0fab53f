"""Packaging: what a wheel or the Docker image of gngdt really contains."""

from __future__ import annotations

import fnmatch
import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())


def _dockerignore() -> list[str]:
    lines = (REPO / ".dockerignore").read_text().splitlines()
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


def _ignored(relative: str, patterns: list[str]) -> bool:
    """Docker's rule, enough for our patterns: a path is out when it or a parent matches."""
    parts = relative.split("/")
    prefixes = ["/".join(parts[: index + 1]) for index in range(len(parts))]
    return any(fnmatch.fnmatch(prefix, pattern.removeprefix("**/"))
               or fnmatch.fnmatch(parts[index], pattern.removeprefix("**/"))
               for pattern in patterns for index, prefix in enumerate(prefixes))


def test_the_docker_build_context_holds_only_what_the_image_needs() -> None:
    patterns = _dockerignore()
    for bulky in ("recordings/tabletop.mcap", "runs/x.rrd", "out/x.rrd", "tests/conftest.py",
                  ".git/HEAD", "services/__pycache__/x.pyc"):
        assert _ignored(bulky, patterns), f"{bulky} would be sent to the Docker daemon"
    copied = [source for line in (REPO / "Dockerfile").read_text().splitlines()
              if line.startswith("COPY ") for source in line.split()[1:-1]]
    assert copied
    for source in copied:
        assert (REPO / source).exists(), f"the Dockerfile copies {source}, which is missing"
        assert not _ignored(source, patterns), f"the Dockerfile copies {source}, ignored"
    # `pip install .` in the image reads these: they must be copied in
    build_inputs = [PYPROJECT["project"]["readme"], *PYPROJECT["project"]["license-files"]]
    for name in build_inputs:
        assert name in copied, f"the Dockerfile does not copy {name}"


def test_readme_says_where_the_shared_data_comes_from_and_what_skips_without_it() -> None:
    readme = (REPO / "README.md").read_text()
    section = readme[readme.index("## Contributing"):]
    assert "../shared" in section
    readers = sorted(path.name for path in (REPO / "tests").rglob("test_*.py")
                     if re.search(r"[\"']shared[\"']", path.read_text()))
    assert readers
    for name in readers:
        assert name in section, f"README's Contributing section does not name {name}"
