"""The MCAP recorder under the .rrd's bounds (issue 24.3): a size cap, a complete file when it
stops, 16 cameras, only gngdt's streams, a queue bounded in bytes; files read back with the
mcap package."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from gngdt.io.outputs.mcap import McapRecorder, footer_without_summary
from gngdt.schemas.images import image_to_raw
from gngdt.schemas.wire import ENCODING_RAW_IMAGE, ENCODING_SCENE_UPDATE, FrameStamp


def image(seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    return image_to_raw(rng.integers(0, 256, (120, 160, 3), dtype=np.uint8),
                        timestamp_ns=time.time_ns()).SerializeToString()  # 57 kB, incompressible


def attachment(sequence: int) -> bytes:
    return FrameStamp(sequence, time.time_ns()).to_attachment()


def local_session():
    """A zenoh session that opens no socket (no listener, no scouting): its own puts reach its
    own subscribers."""
    import zenoh

    config = zenoh.Config()
    for key, value in (("mode", '"peer"'), ("listen/endpoints", "[]"),
                       ("scouting/multicast/enabled", "false"),
                       ("scouting/gossip/enabled", "false")):
        config.insert_json5(key, value)
    return zenoh.open(config)


def read_back(path: Path) -> tuple[list[str], object]:
    with open(path, "rb") as file:
        reader = make_reader(file)
        topics = [channel.topic for _, channel, _ in reader.iter_messages()]
        return topics, reader.get_summary()


def test_the_recording_stops_at_its_cap_finished_and_readable(tmp_path: Path) -> None:
    path = tmp_path / "capped.mcap"
    recorder = McapRecorder(path, chunk_size=100_000, max_bytes=1_000_000)
    for sequence in range(60):  # 3.4 MB of images for a 1 MB cap
        recorder.put_bytes("gngdt/camera/color", ENCODING_RAW_IMAGE, image(sequence),
                           attachment(sequence))
        time.sleep(0.005)
    recorder.close()
    assert "it reached 1 MB (--max-mcap-mb 1)" in recorder.stopped
    topics, summary = read_back(path)
    assert summary is not None and summary.statistics.message_count == len(topics)
    assert 10 <= len(topics) < 60 and set(topics) == {"/camera/color"}
    assert path.stat().st_size < 1_000_000 + 2 * 100_000 + 60_000  # a chunk past, at most


def test_cameras_beyond_sixteen_and_foreign_streams_make_no_channel(tmp_path: Path) -> None:
    path = tmp_path / "cameras.mcap"
    recorder = McapRecorder(path)
    session = local_session()
    try:
        session.declare_subscriber("gngdt/**", recorder.put)
        for index in range(100):
            session.put(f"gngdt/made-up-{index}/objects", b"", encoding=ENCODING_SCENE_UPDATE,
                        attachment=attachment(index))
        for stream in ("made-up", "objects/deeper", "learner/instance/x"):
            session.put(f"gngdt/made-up-0/{stream}", b"", encoding=ENCODING_SCENE_UPDATE,
                        attachment=attachment(0))
        time.sleep(0.5)
    finally:
        session.close()
    recorder.close()
    topics, summary = read_back(path)
    assert len(summary.channels) == 16 and len(topics) == 16
    assert recorder.skipped == 84 + 3


def test_the_queue_is_bounded_in_bytes(tmp_path: Path) -> None:
    """A sample larger than the queue's room is dropped and counted (checked on its size, before
    it is copied out of zenoh); what is queued is freed as it is written."""
    recorder = McapRecorder(tmp_path / "queue.mcap", max_queued_bytes=200_000)
    session = local_session()
    try:
        session.declare_subscriber("gngdt/**", recorder.put)
        session.put("gngdt/camera/color", b"\x00" * 300_000, encoding=ENCODING_RAW_IMAGE,
                    attachment=attachment(0))
        for sequence in range(1, 11):
            session.put("gngdt/camera/color", image(sequence), encoding=ENCODING_RAW_IMAGE,
                        attachment=attachment(sequence))
            time.sleep(0.05)
        time.sleep(0.5)
    finally:
        session.close()
    recorder.close()
    assert recorder.dropped == 1 and recorder.written == 10
    assert recorder._queued_bytes == 0


def test_a_file_cut_after_its_last_chunk_and_closed_with_a_footer_reads(tmp_path: Path) -> None:
    """What a failed write leaves: the records written so far, a data-end and a footer
    without summary; readers scan it."""
    from mcap.writer import CompressionType, Writer

    whole = tmp_path / "whole.mcap"
    with open(whole, "wb") as file:
        writer = Writer(file, chunk_size=50_000, compression=CompressionType.LZ4)
        writer.start()
        schema = writer.register_schema("foxglove.RawImage", "protobuf", b"")
        channel = writer.register_channel("/camera/color", "protobuf", schema)
        for sequence in range(10):
            writer.add_message(channel, log_time=sequence, data=image(sequence),
                               publish_time=sequence)
        writer.flush()
        complete = file.tell()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[:complete] + footer_without_summary())
    topics, summary = read_back(cut)
    assert topics == ["/camera/color"] * 10 and summary is None
