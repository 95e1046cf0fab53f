"""What leaves gngdt for Foxglove and rerun: the --mcap recording, objects and scene updates,
and the services' behaviour when these are flooded or never read."""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers.processes import log_text, wait_for

from gngdt.schemas.wire import ENCODING_SCENE_UPDATE, FrameStamp

REPO_ROOT = Path(__file__).resolve().parents[2]
#: the rerun CLI installed beside this Python (the venv's, even when the venv is not activated)
RERUN = shutil.which("rerun", path=str(Path(sys.executable).parent)) or "rerun"

CAMERA_CHANNELS = {
    "/camera/color": "foxglove.RawImage",
    "/camera/depth": "foxglove.RawImage",
    "/camera/calibration": "foxglove.CameraCalibration",
    "/camera/points": "foxglove.PointCloud",
    "/camera/topology": "gngdt.Topology",
    "/camera/learner/status": "gngdt.LearnerStatus",
    "/camera/objects": "foxglove.SceneUpdate",
    "/camera/scene": "foxglove.SceneUpdate",
    "/camera/eos": "gngdt.StreamEnd",
    "/tf": "foxglove.FrameTransform",  # the synthetic camera moves: its pose, per frame
}


def _recorded(out: Path, recording: Path, *options: str) -> dict[str, Path]:
    """``gngdt run`` of ``recording`` with ``--mcap`` and ``options``: the .rrd and the MCAP
    it wrote."""
    paths = {"rrd": out / "run.rrd", "mcap": out / "run.mcap"}
    completed = subprocess.run(
        [sys.executable, "-m", "gngdt.services.cli", "run", str(recording),
         "--save", str(paths["rrd"]), "--mcap", str(paths["mcap"]),
         "--samples-per-frame", "10000", *options],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=150)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert f"mcap:               {paths['mcap']}" in completed.stdout
    assert ".rrd size:" in completed.stdout and "1 frame in 3" in completed.stdout
    return paths


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory, tabletop_recording: Path) -> dict[str, Path]:
    """The 8-frame tabletop, every learned frame published (``--publish-every 0``)."""
    return _recorded(tmp_path_factory.mktemp("recorded-run"), tabletop_recording,
                     "--publish-every", "0")


@pytest.mark.timeout(200)
def test_a_replay_publishes_on_its_own_clock(tmp_path: Path, tabletop_recording: Path) -> None:
    """By default what was learned is published at most every 0.1 s of the recording's own
    time, counted from the frames' stamps as the contract says, and the last frame settled:
    the same frames on any machine (a replay stalled for a second may add one)."""
    from gngdt.io.mcap.reader import read_frames
    from gngdt.schemas.topology import decode_topology

    stamps = [frame.timestamp_ns for frame in read_frames(tabletop_recording)]
    expected, last = [], None
    for sequence, stamp in enumerate(stamps):
        if last is None or stamp - last >= 100_000_000 - 2_000_000:
            expected.append(sequence)
            last = stamp
    expected.append(len(stamps) - 1)  # the settled network
    assert 2 < len(set(expected)) < len(stamps)  # the recording shows the rule, not its edge
    messages = _decoded(_recorded(tmp_path, tabletop_recording)["mcap"])
    published = [decode_topology(entry[1].SerializeToString()).frame_sequence
                 for entry in messages["/camera/topology"]]
    statuses = [entry[1] for entry in messages["/camera/learner/status"]]
    assert statuses[-1].settled and statuses[-1].frames_used == len(stamps)
    assert set(expected) <= set(published) and len(set(published)) < len(stamps), published
    assert published[-1] == len(stamps) - 1


def _decoded(path: Path) -> dict[str, list[tuple[int, object, str]]]:
    """topic -> [(log_time, decoded protobuf message, schema name)] read with mcap + protobuf."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    messages: dict[str, list] = defaultdict(list)
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            messages[channel.topic].append((message.log_time, decoded, schema.name))
    return messages


@pytest.mark.timeout(200)
def test_mcap_holds_every_stream_with_foxglove_schemas(recorded_run) -> None:
    messages = _decoded(recorded_run["mcap"])
    assert set(messages) == set(CAMERA_CHANNELS)
    for topic, schema in CAMERA_CHANNELS.items():
        assert {entry[2] for entry in messages[topic]} == {schema}, topic
        times = [entry[0] for entry in messages[topic]]
        assert times == sorted(times), f"{topic}: log times go backwards"
    assert len(messages["/camera/color"]) == 8
    transforms = [entry[1] for entry in messages["/tf"]]
    assert len(transforms) == 8
    assert {(t.parent_frame_id, t.child_frame_id) for t in transforms} == {("world", "camera")}
    scenes = [entry[1] for entry in messages["/camera/scene"]]
    objects = [entry[1] for entry in messages["/camera/objects"]]
    # one objects update per learned frame and one for the settled network (published before
    # the settled status the logger ends on); objects and scene are latest-wins (congestion
    # control DROP, docs/contracts.md), so on a busy machine any but the settled network's may
    # be dropped on the way to the logger (a fresh clone's suite beside other work kept 3 of 9
    # objects updates and 1 scene): how many arrive is the machine's, not a property of gngdt
    learned = max(entry[1].frames_used for entry in messages["/camera/learner/status"])
    assert learned >= 1 and 1 <= len(objects) <= learned + 1 and len(scenes) >= 1
    for update in scenes + objects:
        assert update.deletions[0].type == update.deletions[0].ALL  # the newest state only
    scene = scenes[-1]
    entities = {entity.id: entity for entity in scene.entities}
    assert {"nodes", "edges/pos", "edges/col", "edges/nor", "edges/col+nor"} <= set(entities)
    nodes = len(entities["nodes"].spheres)
    assert nodes > 50
    for name in ("edges/pos", "edges/col+nor"):
        line = entities[name].lines[0]
        assert line.type == line.LINE_LIST and len(line.points) == nodes
        assert len(line.colors) == nodes and len(line.indices) % 2 == 0
    assert len(entities["edges/pos"].lines[0].indices) >= 2 * nodes  # a mesh, not a chain
    # objects and scene are in the frame the nodes are learned in (the synthetic camera moves:
    # its clouds come in the scene's fixed frame "world")
    frames = {entry[1].frame_id for entry in messages["/camera/topology"]}
    assert frames == {"world"}
    assert {entity.frame_id for entity in scene.entities} == frames
    # a cluster is an object once seen in object_confirm_frames (5) learned frames in a row:
    # the first (up to 4) updates are empty, every one after has objects, and the settled
    # network's (the last) has its objects whatever the confirmation
    unconfirmed = next(i for i, update in enumerate(objects) if update.entities)
    assert unconfirmed <= min(4, len(objects) - 1)
    objects = objects[unconfirmed:]
    for update in objects:
        assert update.entities, "every learned frame after the first objects has objects"
        for entity in update.entities:
            assert entity.id.startswith("object/") and entity.frame_id in frames
            assert entity.cubes and entity.texts
            size = entity.cubes[0].size
            assert min(size.x, size.y, size.z) >= 0 and max(size.x, size.y, size.z) > 0.05
            metadata = {pair.key: pair.value for pair in entity.metadata}
            assert int(metadata["node_count"]) > 0 and len(metadata["centroid"].split()) == 3
    # objects (segments by default) keep their ids from frame to frame, even while the network
    # is still growing (frames 5-8 and the settled network)
    kept = seen = 0
    for before, after in itertools.pairwise(objects):
        sizes = {entity.id: int({pair.key: pair.value for pair in entity.metadata}["node_count"])
                 for entity in before.entities}
        big = {name for name, count in sizes.items() if count >= 10}
        seen += len(big)
        kept += len(big & {entity.id for entity in after.entities})
    assert seen >= len(objects) and kept / seen >= 0.8, (kept, seen)


@pytest.mark.timeout(200)
def test_topologies_carry_persistent_node_and_cluster_ids(recorded_run) -> None:
    from gngdt.schemas.topology import decode_topology

    # the MCAP's own schema decodes them; our decoder then validates the same bytes
    messages = _decoded(recorded_run["mcap"])
    topologies = [decode_topology(entry[1].SerializeToString())
                  for entry in messages["/camera/topology"]]
    learned = max(entry[1].frames_used for entry in messages["/camera/learner/status"])
    # each learned frame's and the settled one were published; topologies are latest-wins, all
    # but the settled one (sent with congestion control BLOCK), so a busy logger may miss some
    assert learned >= 1 and 1 <= len(topologies) <= learned + 1
    assert topologies[-1].settled and not any(snapshot.settled for snapshot in topologies[:-1])
    # in frame order, the settled network last (it is the last frame's, which may be there too)
    sequences = [snapshot.frame_sequence for snapshot in topologies]
    assert all(a < b for a, b in itertools.pairwise(sequences[:-1])), sequences
    assert max(sequences) == sequences[-1], sequences
    previous = None
    for snapshot in topologies:
        assert snapshot.node_ids is not None and np.unique(snapshot.node_ids).size == len(
            snapshot.node_ids)
        assert set(snapshot.cluster_ids) == set(snapshot.clusterings)
        if previous is not None:
            # nodes persist: most of the previous frame's node ids are still there
            kept = np.isin(previous.node_ids, snapshot.node_ids).mean()
            assert kept > 0.9
            # the biggest position cluster keeps its id (its nodes persist)
            assert snapshot.cluster_ids["pos"][0] == previous.cluster_ids["pos"][0]
        previous = snapshot


@pytest.mark.timeout(200)
def test_rerun_opens_the_mcap_and_the_rrd_shows_objects_with_ids(recorded_run, tmp_path) -> None:
    from rerun.chunk import RrdReader

    converted = tmp_path / "from-mcap.rrd"
    completed = subprocess.run(
        [RERUN, "mcap", "convert", str(recorded_run["mcap"]), "-o", str(converted)],
        capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert completed.returncode == 0, completed.stderr
    columns: dict[str, set[str]] = defaultdict(set)
    for chunk in RrdReader(str(converted)).stream().collect().stream():
        columns[str(chunk.entity_path)].update(chunk.to_record_batch().schema.names)
    assert "Image:buffer" in columns["/camera/color"]
    assert "Points3D:positions" in columns["/camera/points"]
    assert "Pinhole:image_from_camera" in columns["/camera/calibration"]
    assert "foxglove.SceneUpdate:message" in columns["/camera/scene"]
    assert "foxglove.SceneUpdate:message" in columns["/camera/objects"]

    logged: dict[str, set[str]] = defaultdict(set)
    for chunk in RrdReader(str(recorded_run["rrd"])).stream().collect().stream():
        logged[str(chunk.entity_path)].update(chunk.to_record_batch().schema.names)
    assert {"Boxes3D:centers", "Boxes3D:half_sizes", "Boxes3D:labels"} <= logged["/world/objects"]
    assert any("object_id" in name for name in logged["/world/objects"])
    for clustering in ("pos", "col", "nor", "col\\+nor"):
        assert "LineStrips3D:colors" in logged[f"/world/gng/edges/{clustering}"]
    # the nodes once, with every clustering's colours beside their learned ones
    assert {"Points3D:positions", "Points3D:colors"} <= logged["/world/gng/nodes"]
    for clustering in ("segments", "pos", "col", "nor", "col+nor"):
        assert f"gngdt.clusters.{clustering}:colors" in logged["/world/gng/nodes"]


@pytest.mark.timeout(200)
def test_the_rrd_draws_the_final_settled_network(recorded_run) -> None:
    """Topologies are drawn 1 frame in 3, but the file opens on its last frame: the network
    drawn there is the one the learner settled on after the end of the stream."""
    from rerun.chunk import RrdReader

    drawn: list[tuple[int, int]] = []
    counted: list[tuple[int, float]] = []
    for chunk in RrdReader(str(recorded_run["rrd"])).stream().collect().stream():
        batch = chunk.to_record_batch()
        frames = batch.column("frame").to_pylist() if "frame" in batch.schema.names else []
        if str(chunk.entity_path) == "/world/gng/nodes":
            drawn += zip(frames, map(len, batch.column("Points3D:positions").to_pylist()),
                         strict=True)
        elif str(chunk.entity_path) == "/metrics/nodes":
            counted += zip(frames, np.ravel(batch.column("Scalars:scalars").to_pylist()),
                           strict=True)
    last_frame, final_nodes = counted[-1]  # in logging order: the settled network's count
    assert final_nodes == max(nodes for _, nodes in counted)
    assert drawn[-1] == (last_frame, final_nodes)


def _objects_flood(count: int, rng: np.random.Generator) -> bytes:
    """An objects update with ``count`` fresh random ids."""
    from gngdt.schemas.scene import objects_to_scene_update

    ones = np.ones((count, 3))
    return objects_to_scene_update(
        ids=rng.integers(0, 2**62, count), centers=rng.random((count, 3)),
        quaternions_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (count, 1)), sizes=ones * 0.1,
        colors=np.full((count, 3), 200, np.uint8), node_counts=np.full(count, 5),
        centroids=ones, mean_colors=ones, normals=ones, timestamp_ns=time.time_ns(),
        frame_id="camera").SerializeToString()


def _rss_mb(pid: int, field: str = "VmRSS") -> float:
    """A memory field of /proc/<pid>/status in MB: VmRSS (resident), RssAnon (resident and
    private: the heap, where queued messages would be; not the shared-memory pools)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no {field} for {pid}")


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_logger_survives_an_objects_topic_flooded_with_ids(
    router_endpoint: str, spawn: Callable, tmp_path: Path
) -> None:
    import zenoh
    from rerun.chunk import RrdReader

    from gngdt.schemas.scene import MAX_OBJECTS
    from gngdt.services.plumbing.session import client_config, open_config

    rrd_path = tmp_path / "flood.rrd"
    queue_mb = 64
    logger = spawn("log", "--save", str(rrd_path), "--keep-running",
                   "--zenoh-connect", router_endpoint, "--max-queue-mb", str(queue_mb))
    session = open_config(client_config([router_endpoint]))
    rng = np.random.default_rng(0)
    try:
        deadline = time.monotonic() + 60
        while not list(session.liveliness().get("gngdt/logger/alive/**", timeout=1)):
            assert time.monotonic() < deadline, "logger never came up"
        publisher = session.declare_publisher(
            "gngdt/camera/objects", encoding=ENCODING_SCENE_UPDATE,
            congestion_control=zenoh.CongestionControl.BLOCK)
        oversized = _objects_flood(MAX_OBJECTS + 1, rng)
        put = 0

        def flood(payload_of: Callable[[], bytes], seconds: float) -> None:
            nonlocal put
            until = time.monotonic() + seconds
            while time.monotonic() < until:
                publisher.put(payload_of(), attachment=FrameStamp(put, time.time_ns())
                              .to_attachment())
                put += 1

        # rounds of fresh ids (500 a message, as fast as we can) and oversized updates. The
        # logger's RSS swings from round to round (a full inbox of up to --max-queue-mb, zenoh's
        # buffers for the large updates, the allocator's arenas; more under load): bounded means
        # no round goes beyond the inbox's bound and the later rounds come back to the first
        # ones' level, where a leak would climb round after round
        rss = [_rss_mb(logger.pid)]
        for _ in range(6):
            flood(lambda: _objects_flood(500, rng), 2.5)
            flood(lambda: oversized, 0.5)
            time.sleep(0.5)  # the last updates logged: what stays, not what is in flight
            rss.append(_rss_mb(logger.pid))
        assert logger.poll() is None
        publisher.put(_objects_flood(3, rng), attachment=FrameStamp(put, time.time_ns())
                      .to_attachment())
        time.sleep(1.5)
    finally:
        session.close()
    logger.send_signal(2)
    assert logger.wait(30) == 0, Path(logger.log_path).read_text()
    assert put > 100
    rounds = f"logger RSS after each round (MB): {[round(mb) for mb in rss]}, {put} messages"
    assert max(rss[1:]) < rss[1] + queue_mb + 150, rounds
    # a leak climbs round after round and lifts every round, the lowest too; a busy machine
    # only fills the inbox more (up to its bound) and the allocator keeps more, in any round:
    # the floor of the last three rounds against the first three's highest. (14 rounds of a
    # quiet run swung 294-477 MB with no trend, so one or two high rounds are no leak: CI once
    # gave 299, 296, 299 then 305, 398, 426 MB)
    assert min(rss[4:]) < max(rss[1:4]) + queue_mb + 30, rounds
    log_text = Path(logger.log_path).read_text()
    assert "more than the limit" in log_text  # the oversized updates were refused, counted
    rows = sum(chunk.num_rows for chunk in RrdReader(str(rrd_path)).stream().collect().stream()
               if str(chunk.entity_path) == "/world/objects")
    assert 0 < rows <= put


_STUCK_CONSUMER = """
import sys, time
import zenoh
from gngdt.services.plumbing.session import client_config, open_config
session = open_config(client_config([sys.argv[1]]))
# a consumer that never reads: once its one-slot FIFO is full, zenoh's receiving thread for this
# session blocks (FifoChannel semantics), so the router cannot hand it anything more
subscribers = [session.declare_subscriber(key, zenoh.handlers.FifoChannel(1))
               for key in ("gngdt/camera/scene", "gngdt/camera/objects")]
print("subscribed", flush=True)
time.sleep(3600)
"""


WATCH_SECONDS = 12.0


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_a_scene_consumer_that_never_reads_stalls_nothing(
    free_port: int, spawn: Callable, tabletop_recording: Path, tmp_path: Path
) -> None:
    from gngdt.schemas.status import decode_status
    from gngdt.services.plumbing.session import client_config, open_config

    endpoint = f"tcp/127.0.0.1:{free_port}"
    connect = ("--zenoh-connect", endpoint)
    router = spawn("router", "--listen", endpoint)
    wait_for(lambda: "listening on" in log_text(router), 30, "the router")
    learner = spawn("learn", "--samples-per-frame", "2000", "--scene-every", "1", *connect)
    stuck = subprocess.Popen([sys.executable, "-c", _STUCK_CONSUMER, endpoint], cwd=REPO_ROOT,
                             stdout=subprocess.PIPE, text=True, start_new_session=True)
    session = open_config(client_config([endpoint]))
    statuses: list[tuple[float, object]] = []
    session.declare_subscriber("gngdt/camera/learner/status", lambda sample: statuses.append(
        (time.monotonic(), decode_status(sample.payload.to_bytes()))))
    try:
        assert stuck.stdout.readline().strip() == "subscribed"
        deadline = time.monotonic() + 60
        while not list(session.liveliness().get("gngdt/camera/learner/alive", timeout=1)):
            assert time.monotonic() < deadline, "learner never came up"
        spawn("capture", str(tabletop_recording), "--loop", *connect)
        # zenoh's buffers towards the stuck consumer fill in the first seconds (router and
        # learner each grow by up to ~70 MB once, then stay flat): measured after that
        # private memory only: the shared-memory pools (a fixed number of payloads per
        # publisher) enter VmRSS page by page as they are first used, which is not queueing
        time.sleep(6.0)
        router_warm = _rss_mb(router.pid, "RssAnon")
        learner_warm = _rss_mb(learner.pid, "RssAnon")
        started = time.monotonic()
        time.sleep(WATCH_SECONDS)
        assert learner.poll() is None and router.poll() is None
        router_grown = _rss_mb(router.pid, "RssAnon") - router_warm
        learner_grown = _rss_mb(learner.pid, "RssAnon") - learner_warm
        arrivals = [at for at, _ in statuses if at >= started]
        recent = [status for at, status in statuses if at >= started]
    finally:
        session.close()
        stuck.kill()
        stuck.wait()
    # the learner never waited for the stuck consumer: with a blocking publisher it stalls for
    # seconds here (until the router gives up on the consumer's link); latest-wins, never
    # (bounds with margin for a busy machine: a frame of 2,000 steps takes milliseconds, a
    # stall the router's 1 s cut-off per put, again and again)
    gaps = np.diff([started, *arrivals, started + WATCH_SECONDS])
    assert gaps.max() < 3.0, f"no status for {gaps.max():.1f} s"
    assert recent[-1].frames_used - recent[0].frames_used >= WATCH_SECONDS
    # hundreds of scene updates of ~100 kB each were refused to the stuck consumer, not queued
    assert router_grown < 40 and learner_grown < 40, (router_grown, learner_grown)
