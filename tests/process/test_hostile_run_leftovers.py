"""What a run or a flood leaves behind (issue 38): the credentials of a `gngdt run` killed with
SIGKILL (0600 files in its private folder, before left for ever) are removed by the next
`gngdt run`; the ROS 2 bridge gives the memory of an image flood back (before: 846 of its 882 MB
peak kept 10 s after a 1920x1080 flood)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.processes import log_text
from hostile_doors import bridge_under_flood
from hostile_trust import run_credentials


@pytest.mark.timeout(300)
def test_a_killed_runs_credentials_are_removed_by_the_next_run(
        tabletop_recording: Path, one_frame_recording: Path, spawn: Callable,
        tmp_path: Path) -> None:
    killed = spawn("run", str(tabletop_recording), "--rate", "0.1", "--save",
                   str(tmp_path / "killed.rrd"))
    folder = run_credentials(killed.pid)
    os.killpg(killed.pid, signal.SIGKILL)
    killed.wait(30)
    assert (folder / "router-users.txt").exists()  # what the kill left: the passwords
    nxt = spawn("run", str(one_frame_recording), "--fast", "--save", str(tmp_path / "next.rrd"))
    assert nxt.wait(240) == 0, log_text(nxt)[-3000:]
    assert not (folder / "router-users.txt").exists()
    assert not list(folder.glob("*.json5")) if folder.exists() else True


def test_only_the_credentials_of_ended_runs_are_removed(tmp_path: Path) -> None:
    """A folder whose run lives (this process) stays; one whose pid ended, or was reused by
    another process (another start time), is cleaned; the logs of a failed run stay."""
    from gngdt.services.plumbing.roles import (
        OWNER_FILE,
        process_start,
        remove_stale_credentials,
    )

    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()

    def run_folder(name: str, owner: str) -> Path:
        folder = tmp_path / f"gngdt-run-{name}"
        folder.mkdir(mode=0o700)
        (folder / OWNER_FILE).write_text(owner)
        (folder / "router-users.txt").write_text("capture:secret\n")
        (folder / "capture.json5").write_text("{}")
        return folder

    # a run killed whose parent has not reaped it yet (an orphan waits for init): a zombie
    zombie = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while process_state(zombie.pid) != "Z" and time.monotonic() < deadline:
        time.sleep(0.01)
    assert process_state(zombie.pid) == "Z"

    alive = run_folder("alive", f"{os.getpid()} {process_start(os.getpid())}\n")
    gone = run_folder("gone", f"{ended.pid} 1\n")
    reused = run_folder("reused", f"{os.getpid()} 1\n")
    dead = run_folder("zombie", f"{zombie.pid} {process_start(zombie.pid)}\n")
    (reused / "learn.log").write_text("what failed")
    try:
        assert sorted(remove_stale_credentials(tmp_path)) == [gone, reused, dead]
    finally:
        zombie.wait()
    assert (alive / "router-users.txt").exists()
    assert not gone.exists()  # emptied, removed
    assert [path.name for path in reused.iterdir()] == ["learn.log"]


def process_state(pid: int) -> str:
    """A process's state letter (R, S, Z, ...), from /proc."""
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]


@pytest.mark.timeout(180)
def test_the_bridge_gives_an_image_floods_memory_back(tmp_path: Path) -> None:
    outcome = bridge_under_flood(tmp_path, seconds=6.0, width=1920, height=1080, settle_s=6.0)
    assert outcome.images > 50
    assert outcome.peak_mb < 1024
    # what stays beyond its shared-memory publishing pools (sized once, reused): not the flood
    kept = outcome.after_mb - outcome.after_shared_mb - outcome.before_mb
    assert kept < 0.5 * (outcome.peak_mb - outcome.before_mb), vars(outcome)
    assert "Traceback" not in outcome.log
