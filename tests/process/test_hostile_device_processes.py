"""RealSense recordings made odd on purpose (issue 38), through the commands a user runs: each is
the file's problem, exit status 2 with the file named, never a traceback (before: a RuntimeError
from the SDK's processing block, a TypeError, or the process killed by the SDK)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from helpers.processes import log_text
from helpers.realsense import require_pyrealsense

require_pyrealsense()

from hostile_doors import odd_realsense_recordings  # noqa: E402


@pytest.fixture(scope="module")
def odd(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return odd_realsense_recordings(tmp_path_factory.mktemp("realsense_odd"))


@pytest.mark.timeout(240)
@pytest.mark.parametrize(("name", "said"), [
    ("huge", "stream calibration refused"),
    ("wide", "exceed the limit of"),
    ("text_metadata", "stored as TEXT, not as BLOB"),
])
def test_run_on_an_odd_realsense_file_says_why_and_exits_2(
        odd: dict[str, Path], spawn: Callable, tmp_path: Path, name: str, said: str) -> None:
    run = spawn("run", str(odd[name]), "--fast", "--save", str(tmp_path / "out.rrd"))
    assert run.wait(180) == 2, log_text(run)[-3000:]
    log = log_text(run)
    assert said in log and f"{name}.db3" in log
    assert "Traceback" not in log


@pytest.mark.timeout(120)
def test_record_converting_an_odd_realsense_file_says_why(
        odd: dict[str, Path], spawn: Callable, tmp_path: Path) -> None:
    record = spawn("record", "realsense", "--from", str(odd["huge"]), "--out",
                   str(tmp_path / "out.mcap"))
    assert record.wait(90) == 2, log_text(record)[-3000:]
    assert "stream calibration refused" in log_text(record)
    assert "Traceback" not in log_text(record)
