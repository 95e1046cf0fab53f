"""`gngdt run` waits for its services while they make progress (a first run compiles kernels for
tens of seconds, longer on a busy machine), and gives up only on a silent one, naming it."""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from gngdt.services.run import Child, Observed, Pipeline, wait_for_startup

#: a child that keeps busy and says where it is, as the learner does while compiling
BUSY = """
import time
deadline = time.monotonic() + 60
step = 0
while time.monotonic() < deadline:
    x = sum(range(20000))
    if step % 2000 == 0:
        print(f"INFO compiling kernels {step // 2000 + 1}/9: group", flush=True)
    step += 1
"""
#: a child that does nothing at all: no CPU time, no output
SILENT = "import time; time.sleep(60)"


def _child(name: str, code: str, tmp_path: Path) -> Child:
    stderr_path = tmp_path / f"{name}.log"
    stderr_file = open(stderr_path, "wb")  # closed by Pipeline.close
    process = subprocess.Popen([sys.executable, "-c", code], stdout=stderr_file,
                               stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    return Child(name, process, stderr_path, stderr_file)


@pytest.fixture
def pipeline(tmp_path: Path):
    pipeline = Pipeline(access=None, log_dir=tmp_path, log_level="INFO")
    yield pipeline
    pipeline.close()  # kills every child still running, by its process


def test_a_silent_child_is_given_up_on_and_named(pipeline: Pipeline, tmp_path: Path) -> None:
    busy, silent = _child("learn", BUSY, tmp_path), _child("log", SILENT, tmp_path)
    pipeline.children += [busy, silent]
    starting = {busy: "gngdt/camera/learner/alive", silent: "gngdt/logger/alive"}
    assert wait_for_startup(starting, Observed(), 1.0, threading.Event(), pipeline) is silent


def test_a_child_making_progress_is_waited_for_and_its_steps_shown(
        pipeline: Pipeline, tmp_path: Path, caplog) -> None:
    busy = _child("learn", BUSY, tmp_path)
    pipeline.children.append(busy)
    stop = threading.Event()
    threading.Timer(4.0, stop.set).start()  # ends the wait: the busy child never comes up
    with caplog.at_level(logging.INFO, logger="gngdt.services.run"):
        assert wait_for_startup({busy: "gngdt/camera/learner/alive"}, Observed(), 1.0, stop,
                                pipeline) is None
    assert stop.is_set()  # still waiting after 4 s, with a 1 s silence limit
    shown = [record.getMessage() for record in caplog.records]
    assert any(message.startswith("learn: compiling kernels 1/9") for message in shown), shown
