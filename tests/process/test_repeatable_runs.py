"""A file is read completely and repeatably: `gngdt run` hands every frame to the learner in order,
each once the learner took the one before, so the same file with the same seed gives the same
network bit for bit on a quiet or a busy machine, and `gngdt eval recording` learns exactly what
`gngdt run` learns; a learner that leaves or stalls ends the replay with the reason."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from procstat import busy_processes

from gngdt.io.checkpoints import load_checkpoint

REPO_ROOT = Path(__file__).resolve().parents[2]
GNGDT = [sys.executable, "-m", "gngdt.services.cli"]


def run_file(recording: Path, workdir: Path, *options: str) -> tuple[str, dict[str, np.ndarray]]:
    """`gngdt run` on ``recording``; its summary and the learner's final state (checkpoint)."""
    workdir.mkdir()
    checkpoint = workdir / "learner.npz"
    completed = subprocess.run(
        [*GNGDT, "run", str(recording), "--save", str(workdir / "run.rrd"), "--checkpoint",
         str(checkpoint), *options],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=400)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    state, _ = load_checkpoint(checkpoint)
    return completed.stdout, state


#: what a learner's state holds of the wall clock: the time the replay started anchors the
#: stamps (their differences, which learning uses, are the recording's)
WALL_CLOCK = {"tracker_stamp_ns"}


def assert_same_network(first: dict[str, np.ndarray], second: dict[str, np.ndarray]) -> None:
    assert first.keys() == second.keys()
    for key in first.keys() - WALL_CLOCK:
        np.testing.assert_array_equal(first[key], second[key], err_msg=key)


@pytest.mark.timeout(900)
@pytest.mark.parametrize("options", [(), ("--track",)], ids=["posed", "tracked"])
def test_a_file_replayed_twice_gives_the_same_network_quiet_or_busy(
        options: tuple[str, ...], tabletop_recording: Path, tmp_path: Path) -> None:
    """With ``--track`` too: the tracker's thread poses each frame against the map of the frames
    before it, one frame at a time."""
    quiet, quiet_state = run_file(tabletop_recording, tmp_path / "quiet", *options)
    with busy_processes(2):
        busy, busy_state = run_file(tabletop_recording, tmp_path / "busy", *options)
    for summary in (quiet, busy):
        assert "mode:               every frame" in summary, summary
        assert "frames learned:     8 of 8 sent (100%)" in summary, summary
        assert "every frame sent:   8 = 8 learned + 0 dropped + 0 malformed + 0 refused\n" \
            in summary, summary
        if options:
            assert "tracking:           8 of 8 frames posed (100%); 0 lost" in summary, summary
    assert quiet_state["pos"].shape[0] > 50
    assert_same_network(quiet_state, busy_state)
    figures = [re.search(r"nodes:\s+(\d+)[\s\S]*clusters:\s+(.*)", summary).groups()
               for summary in (quiet, busy)]
    assert figures[0] == figures[1]


@pytest.mark.timeout(900)
def test_eval_recording_learns_what_run_learns(tabletop_recording: Path, tmp_path: Path) -> None:
    from gngdt.eval.recording_eval import MethodReplay, RecordingSettings, frame_points

    _, run_state = run_file(tabletop_recording, tmp_path / "run")
    settings = RecordingSettings(methods=("GNG-DT",), settle=True)
    replay = MethodReplay("GNG-DT", 0, settings)
    last = None
    for points in frame_points(tabletop_recording, settings):
        replay.learn(points)
        last = points
    replay.settle(last)
    assert_same_network(run_state, replay.model.get_state())


@pytest.mark.timeout(600)
def test_realtime_keeps_the_recorded_pace_and_says_so(tabletop_recording: Path,
                                                     tmp_path: Path) -> None:
    summary, _ = run_file(tabletop_recording, tmp_path / "realtime", "--realtime")
    assert "mode:               real time (--realtime)" in summary, summary
    assert re.search(r"frames sent:\s+8 of 8", summary), summary


def wait_for_line(process: subprocess.Popen, pattern: str, lines: list[str]) -> None:
    """Read ``process``'s output until a line matches ``pattern`` (readiness, not sleep)."""
    for line in process.stdout:
        lines.append(line)
        if re.search(pattern, line):
            return
    raise AssertionError(f"{pattern!r} never came:\n{''.join(lines)}")


@pytest.mark.timeout(600)
@pytest.mark.parametrize("how", ["killed", "stalled"])
def test_a_learner_that_leaves_or_stalls_ends_a_paced_capture_with_the_reason(
        how: str, router_endpoint: str, tabletop_recording: Path) -> None:
    connect = ["--zenoh-connect", router_endpoint, "--log-level", "DEBUG"]
    learner = subprocess.Popen([*GNGDT, "learn", *connect], cwd=REPO_ROOT, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    capture = None
    learner_lines: list[str] = []
    try:
        wait_for_line(learner, r"learning from gngdt/camera/points", learner_lines)
        capture = subprocess.Popen(
            [*GNGDT, "capture", str(tabletop_recording), "--rate", "0.2",
             "--learner-timeout", "5", *connect],
            cwd=REPO_ROOT, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        capture_lines: list[str] = []
        wait_for_line(capture, r"frame 1: \d+ points", capture_lines)  # paced: frame 0 taken
        os.kill(learner.pid, signal.SIGKILL if how == "killed" else signal.SIGSTOP)
        rest, _ = capture.communicate(timeout=120)
        text = "".join(capture_lines) + rest
        assert capture.returncode == 1, text
        expected = {"killed": "left (its liveliness token is gone) and did not come back",
                    "stalled": "took no frame for 5 s"}[how]
        assert expected in text and "ending the stream" in text, text
        assert re.search(r"sent [1-7] frames of", text), text
        assert "Traceback" not in text
    finally:
        for process in (capture, learner):
            if process is not None and process.poll() is None:
                process.kill()
                process.communicate()
