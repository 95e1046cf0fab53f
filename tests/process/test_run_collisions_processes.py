"""Runs that never collide (issue 24.4): a busy --serve port is an error before anything
starts, two runs started together write and name their own files, and an existing --save or
--mcap file is refused unless --overwrite."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from gngdt.services.plumbing.session import free_tcp_port

REPO_ROOT = Path(__file__).resolve().parents[2]


def gngdt_run(*arguments: str, cwd: Path = REPO_ROOT) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "gngdt.services.cli", "run", *arguments],
                            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})


@pytest.mark.timeout(120)
def test_a_busy_serve_port_is_an_error_before_anything_starts(tabletop_recording: Path) -> None:
    with socket.socket() as other_viewer:  # what holds the port: another run's viewer, say
        other_viewer.bind(("127.0.0.1", 0))
        other_viewer.listen()
        port = other_viewer.getsockname()[1]
        run = gngdt_run(str(tabletop_recording), "--serve", "--grpc-port", str(port),
                        "--web-port", str(free_tcp_port()))
        out, err = run.communicate(timeout=60)
    assert run.returncode == 2, out + err
    assert f"port {port} on 127.0.0.1 is in use" in err and "--grpc-port" in err
    assert "starting the learner" not in err and "Traceback" not in err


@pytest.mark.timeout(300)
def test_two_runs_started_together_write_and_name_their_own_files(
        tabletop_recording: Path, tmp_path: Path) -> None:
    runs = [gngdt_run(str(tabletop_recording), "--fast", cwd=tmp_path) for _ in range(2)]
    outputs = [run.communicate(timeout=240) for run in runs]
    for run, (out, err) in zip(runs, outputs, strict=True):
        assert run.returncode == 0, out + err
    named = [out.split("rerun:", 1)[1].split()[0] for out, _ in outputs]
    assert named[0] != named[1], named
    written = sorted((tmp_path / "runs").iterdir())
    assert sorted(tmp_path / name for name in named) == written  # and nothing else
    assert all(path.stat().st_size > 100_000 for path in written)


@pytest.mark.timeout(300)
@pytest.mark.parametrize("option", ["--save", "--mcap"])
def test_an_existing_output_is_refused_unless_overwrite(
        tabletop_recording: Path, tmp_path: Path, option: str) -> None:
    existing = tmp_path / ("earlier.rrd" if option == "--save" else "earlier.mcap")
    existing.write_bytes(b"an earlier run's results")
    out, err = (run := gngdt_run(str(tabletop_recording), "--fast", option,
                                 str(existing), cwd=tmp_path)).communicate(timeout=60)
    assert run.returncode == 2, out + err
    assert f"{option} {existing}: the file exists" in err and "--overwrite" in err
    assert existing.read_bytes() == b"an earlier run's results"
    out, err = (run := gngdt_run(str(tabletop_recording), "--fast", option, str(existing),
                                 "--overwrite", cwd=tmp_path)).communicate(timeout=240)
    assert run.returncode == 0, out + err
    assert str(existing) in out and existing.stat().st_size > 100_000
    assert not list(tmp_path.glob("earlier.1.*"))
