"""The logger under odd or hostile input: cameras it must wait for, cameras it must not grow
for, queues bounded in bytes, topologies bounded by what a learner can send, a bounded .rrd."""

from __future__ import annotations

import time

import pytest

from gngdt.schemas.status import encode_stream_end
from gngdt.schemas.wire import FrameStamp


@pytest.fixture
def dispatcher():
    """The logger's real per-sample path into an in-memory recording."""
    import rerun as rr

    from gngdt.io.outputs.rerun_log import DisplayRates, RerunLog
    from gngdt.io.outputs.rerun_output import RerunOutput
    from gngdt.services.logger.cameras import Cameras
    from gngdt.services.logger.dispatch import Dispatcher

    recording = rr.RecordingStream("gngdt-test")
    recording.memory_recording()
    yield Dispatcher([RerunOutput(RerunLog(recording, DisplayRates(max_cloud_points=100)))],
                     Cameras())
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
    assert not dispatcher.cameras.all_finished(drain_seconds=0.0)
    _eos(dispatcher, "right")
    assert dispatcher.cameras.all_finished(drain_seconds=0.0)


def test_a_capture_that_leaves_without_an_end_of_stream_ends_its_camera(dispatcher) -> None:
    dispatcher.capture_seen("lost", alive=True)
    assert not dispatcher.cameras.all_finished(drain_seconds=0.0)
    dispatcher.capture_seen("lost", alive=False)
    time.sleep(0.01)
    assert dispatcher.cameras.all_finished(drain_seconds=0.0)
    assert not dispatcher.cameras.all_finished(drain_seconds=60.0)  # after the drain, not at once


def _learned(dispatcher, camera: str, sequence: int, settled: bool) -> tuple:
    """Handlers of a learner's topology and status of frame ``sequence`` (``settled``: its
    final ones, after the end of stream)."""
    from gngdt.schemas.status import encode_status
    from gngdt.schemas.topology import encode_topology

    attachment = FrameStamp(sequence, time.time_ns()).to_attachment()
    topology = encode_topology(
        positions=[[0.0, 0.0, 1.0]], colors=None, normals=None, errors=None, edges={},
        clusterings={}, steps=10, frame_sequence=sequence, timestamp_ns=time.time_ns(),
        frame_id="camera", settled=settled).SerializeToString()
    status = encode_status(frame_sequence=sequence, settled=settled,
                           settle_reason="settled" if settled else "").SerializeToString()
    return (lambda: dispatcher.handle(f"gngdt/{camera}/topology", topology, attachment),
            lambda: dispatcher.handle(f"gngdt/{camera}/learner/status", status, attachment))


@pytest.mark.parametrize("order", ["topology, status, eos", "status, topology, eos",
                                   "eos, status, topology", "status, eos, topology"])
def test_a_stream_ends_on_the_settled_network_and_status_in_any_order(dispatcher,
                                                                      order: str) -> None:
    """The logger's subscribers hand samples over on threads of their own: the settled status
    may come before the topology sent ahead of it, the end of stream after both."""
    cameras = dispatcher.cameras
    topology, status = _learned(dispatcher, "camera", 7, settled=False)
    topology(), status()  # the last frame, learned and published before the learner settles
    steps = {"topology": _learned(dispatcher, "camera", 7, settled=True)[0],
             "status": _learned(dispatcher, "camera", 7, settled=True)[1],
             "eos": lambda: _eos(dispatcher, "camera", 7)}
    names = order.split(", ")
    for name in names:
        assert not cameras.all_finished(drain_seconds=60.0), f"finished before its {name}"
        steps[name]()
    assert cameras.all_finished(drain_seconds=60.0)
    topology()  # a new stream's first network: the camera is not done until it settles too
    assert not cameras.all_finished(drain_seconds=60.0)


# ------------------------------------------------------------------------- cameras
def test_garbage_on_new_camera_names_makes_no_camera_and_cameras_are_bounded() -> None:
    import rerun as rr

    from gngdt.io.outputs.rerun_log import RerunLog
    from gngdt.io.outputs.rerun_output import RerunOutput
    from gngdt.schemas.status import encode_status
    from gngdt.services.logger.cameras import Cameras
    from gngdt.services.logger.dispatch import Dispatcher

    class CamerasSeen(RerunOutput):
        """The real rerun output, noting every time the logger tells it of its cameras."""

        def cameras_changed(self, cameras: list[str]) -> None:
            blueprints.append(cameras)
            super().cameras_changed(cameras)

    recording = rr.RecordingStream("gngdt-test")
    recording.memory_recording()
    blueprints: list[list[str]] = []
    dispatcher = Dispatcher([CamerasSeen(RerunLog(recording))], Cameras(max_cameras=3))
    stamp = FrameStamp(1, time.time_ns()).to_attachment()
    for index in range(50):  # a valid attachment, a payload no decoder accepts
        dispatcher.handle(f"gngdt/fake{index}/calibration", b"\x0a\xff\xff\x03", stamp)
    assert dispatcher.cameras.names() == [] and blueprints == [] and dispatcher.malformed == 50
    status = encode_status(frame_sequence=1).SerializeToString()
    for index in range(5):
        dispatcher.handle(f"gngdt/cam{index}/learner/status", status, stamp)
    assert sorted(dispatcher.cameras.names()) == ["cam0", "cam1", "cam2"]
    assert dispatcher.cameras.refused == 2
    assert len(blueprints) == 3  # one blueprint per real camera, not one per message
    recording.disconnect()


# ------------------------------------------------------------------------- topologies
def _topology(nodes: int, edges_per_node: int = 2, clusterings: int = 2, name: str = "pos"):
    import numpy as np

    from gngdt.schemas.topology import encode_topology

    rng = np.random.default_rng(0)
    pairs = rng.integers(0, nodes, (nodes * edges_per_node, 2))
    return encode_topology(
        positions=rng.random((nodes, 3)), colors=None, normals=None, errors=None,
        edges={name: pairs}, clusterings={f"c{i}": np.zeros(nodes, np.int32)
                                          for i in range(clusterings)},
        steps=1, frame_sequence=1, timestamp_ns=1, frame_id="camera").SerializeToString()


@pytest.mark.parametrize(("payload", "match"), [
    (_topology(100, edges_per_node=9), "exceed the limit of 1600"),
    (_topology(10, clusterings=20_000), "20000 clusterings"),
    (_topology(10, name="x" * 65), "longer than 64"),
])
def test_topologies_beyond_what_a_learner_sends_are_refused(payload: bytes, match: str) -> None:
    from gngdt.schemas.messages import MessageError
    from gngdt.schemas.topology import decode_topology

    with pytest.raises(MessageError, match=match):
        decode_topology(payload)


def test_the_edge_limit_is_what_the_kernel_can_hold() -> None:
    from gngdt.core.kernels import layout
    from gngdt.schemas.topology import MAX_EDGES_PER_NODE, decode_topology

    assert MAX_EDGES_PER_NODE == layout.MAX_DEGREE // 2
    assert decode_topology(_topology(100, edges_per_node=8)).node_count == 100


def _metric_chunks_at_30_fps(tmp_path, extra: list[str], seconds: float) -> list[int]:
    """Chunks per metric entity in the .rrd a logger recording opened with ``extra`` options
    writes, after ``seconds`` of 30 fps scalars on 4 entities, ticked as the logger ticks it."""
    import argparse

    from rerun.chunk import RrdReader

    from gngdt.io.outputs.rerun_blueprint import EntityPaths
    from gngdt.io.outputs.rerun_log import RerunLog
    from gngdt.io.outputs.rerun_output import RRD_FLUSH_SECONDS, open_recording
    from gngdt.io.outputs.rerun_sinks import RrdFile
    from gngdt.services.logger import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    path = tmp_path / f"metrics{len(extra)}.rrd"
    rec, _, _, _ = open_recording(parser.parse_args(["--save", str(path), *extra]))
    rerun_log = RerunLog(rec)
    output = RrdFile(rerun_log, path, 0, 0, RRD_FLUSH_SECONDS)
    for sequence in range(int(30 * seconds)):
        rerun_log.set_time(FrameStamp(sequence, time.time_ns()))
        for name in ("a", "b", "c", "d"):
            rerun_log.scalar(EntityPaths("camera"), name, sequence)
        output.tick()
        time.sleep(1 / 30)
    output.close()
    chunks: dict[str, int] = {}
    for chunk in RrdReader(path).stream():
        if chunk.entity_path.startswith("/metrics/"):
            chunks[chunk.entity_path] = chunks.get(chunk.entity_path, 0) + 1
    assert len(chunks) == 4
    return list(chunks.values())


def test_the_rrd_batches_each_entity_over_several_seconds_not_200_ms(tmp_path) -> None:
    # rerun's .rrd writer keeps a footer row per chunk in memory, ~100 bytes per distinct
    # component of the recording: rerun's default batching (a chunk per entity every 200 ms)
    # grew a 30 fps logger by ~20 MB a minute, one per second by ~8 MB
    assert max(_metric_chunks_at_30_fps(tmp_path, [], seconds=3.0)) == 1
