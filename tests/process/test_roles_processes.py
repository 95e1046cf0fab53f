"""`gngdt run`'s router keeps each service to its role (issue 24.2): an end of stream and objects
forged with the logger's or the learner's credentials are neither recorded nor stop the run;
without credentials there is no session at all; the credentials go when the run ends."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers.processes import children, command_line, wait_for

from gngdt.schemas.status import encode_stream_end
from gngdt.schemas.wire import ENCODING_SCENE_UPDATE, FrameStamp
from gngdt.services.plumbing.session import ZenohSetupError, client_config, open_config

REPO_ROOT = Path(__file__).resolve().parents[2]


def zenoh_config_of(pid: int) -> Path:
    """The --zenoh-config file a child of `gngdt run` was started with."""
    arguments = command_line(pid)
    return Path(arguments[arguments.index("--zenoh-config") + 1])


@pytest.mark.timeout(240)
def test_forgeries_with_another_roles_credentials_are_not_recorded_and_do_not_stop_the_run(
        tabletop_recording: Path, tmp_path: Path) -> None:
    import zenoh

    mcap_path = tmp_path / "run.mcap"
    log_path = tmp_path / "run.log"
    with open(log_path, "wb") as output:
        run = subprocess.Popen(
            [sys.executable, "-m", "gngdt.services.cli", "run", str(tabletop_recording), "--rate",
             "0.04", "--save", str(tmp_path / "run.rrd"), "--mcap", str(mcap_path)],
            cwd=REPO_ROOT, stdout=output, stderr=output, start_new_session=True)
    try:
        wait_for(lambda: "replaying" in log_path.read_text(), 120, "the services to come up")
        folder = zenoh_config_of(children(run.pid)[0]).parent
        assert sorted(path.name for path in folder.glob("*.json5")) == [
            "bridge.json5", "capture.json5", "learner.json5", "logger.json5"]
        endpoints = client_config(None, folder / "logger.json5").get_json("connect/endpoints")
        anonymous = client_config(json.loads(endpoints))
        anonymous.insert_json5("connect/timeout_ms", "2000")
        with pytest.raises(ZenohSetupError):
            open_config(anonymous)
        block = zenoh.CongestionControl.BLOCK
        for role in ("logger", "learner"):
            session = open_config(client_config(None, folder / f"{role}.json5"))
            for sequence in range(10):
                attachment = FrameStamp(sequence, time.time_ns()).to_attachment()
                end = encode_stream_end(frames_sent=1, last_frame_sequence=0,
                                        recording=f"forged by {role}")
                session.put("gngdt/camera/eos", end.SerializeToString(),
                            attachment=attachment, congestion_control=block)
                if role != "learner":  # the learner may publish objects: that is its role
                    session.put("gngdt/camera/objects", b"forged objects",
                                encoding=ENCODING_SCENE_UPDATE, attachment=attachment,
                                congestion_control=block)
            session.close()
        assert run.wait(180) == 0, log_path.read_text()
    finally:
        if run.poll() is None:
            run.send_signal(signal.SIGINT)
            run.wait(60)
    text = log_path.read_text()
    assert "frames sent:        8 of 8" in text
    learned = int(text.split("frames learned:")[1].split()[0])
    assert learned >= 4, text  # learning went on after the forged ends of stream
    assert not folder.exists() or not list(folder.glob("*.json5"))  # credentials removed
    from mcap.reader import make_reader

    with open(mcap_path, "rb") as file:
        recorded = [(channel.topic, message.data) for _, channel, message
                    in make_reader(file).iter_messages()]
    assert not [topic for topic, data in recorded if b"forged" in data]
    assert [topic for topic, _ in recorded].count("/camera/eos") == 1
    # the learner's own objects are recorded: every publication's (the stream's clock chooses
    # them: at least one before the end) and the settled network's
    assert [topic for topic, _ in recorded].count("/camera/objects") >= 2
