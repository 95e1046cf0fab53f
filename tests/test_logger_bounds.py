"""The logger under odd or hostile input: cameras it must wait for, cameras it must not grow
for, queues bounded in bytes, topologies bounded by what a learner can send, a bounded .rrd."""

from __future__ import annotations

import time

import pytest

from schemas.packing import encode_stream_end
from schemas.wire import FrameStamp


@pytest.fixture
def dispatcher():
    """The logger's real per-sample path into an in-memory recording."""
    import rerun as rr

    from services.logger import Dispatcher, RerunLog

    recording = rr.RecordingStream("gngdt-test")
    recording.memory_recording()
    yield Dispatcher(RerunLog(recording, max_cloud_points=100))
    recording.disconnect()


def _eos(dispatcher, camera: str, last_sequence: int = 0) -> None:
    message = encode_stream_end(timestamp_ns=time.time_ns(), frames_sent=last_sequence + 1,
                                last_frame_sequence=last_sequence)
    dispatcher.handle(f"gngdt/{camera}/eos", message.SerializeToString(),
                      FrameStamp(last_sequence, time.time_ns()).to_attachment())


def test_a_camera_whose_capture_started_is_waited_for_before_its_first_message(
    dispatcher,
) -> None:
    dispatcher.capture_seen("right", alive=True)  # its capture is up, nothing sent yet
    _eos(dispatcher, "left")
    assert not dispatcher.all_finished(drain_seconds=0.0)
    _eos(dispatcher, "right")
    assert dispatcher.all_finished(drain_seconds=0.0)


def test_a_capture_that_leaves_without_an_end_of_stream_ends_its_camera(dispatcher) -> None:
    dispatcher.capture_seen("lost", alive=True)
    assert not dispatcher.all_finished(drain_seconds=0.0)
    dispatcher.capture_seen("lost", alive=False)
    time.sleep(0.01)
    assert dispatcher.all_finished(drain_seconds=0.0)
    assert not dispatcher.all_finished(drain_seconds=60.0)  # after the drain, not at once
