"""Small MCAP files that would cost a reader far more than their size: made by
``bench_hostile.py`` and by the tests of the reader's bounds (``tests/conftest.py`` puts
benchmarks/ on their path). Each message is on a ``foxglove.RawImage`` channel but holds zeros,
so no frame comes out of any of them."""

from __future__ import annotations

import struct
from pathlib import Path

MB = 1024 * 1024


def _writer(file, compression: str, chunk_size: int):
    """(mcap writer, its /camera/color channel id). A calibration channel is declared too (with
    no message), so that readers get past their first check and meet what the file hides."""
    from mcap.writer import CompressionType, Writer

    writer = Writer(file, compression=CompressionType[compression.upper()], chunk_size=chunk_size)
    writer.start()
    calibration = writer.register_schema("foxglove.CameraCalibration", "protobuf", b"")
    writer.register_channel("/camera/calibration", "protobuf", calibration)
    schema = writer.register_schema("foxglove.RawImage", "protobuf", b"")
    return writer, writer.register_channel("/camera/color", "protobuf", schema)


def zstd_bomb(path: Path, inflated_bytes: int) -> Path:
    """One zstd chunk of ``inflated_bytes`` zeros (a few kB), its size stated honestly."""
    with open(path, "wb") as file:
        writer, channel = _writer(file, "zstd", 2 * inflated_bytes)
        writer.add_message(channel, log_time=1, data=bytes(inflated_bytes), publish_time=1)
        writer.finish()
    return path


def lz4_chunk_hiding_its_size(path: Path, inflated_bytes: int) -> Path:
    """One lz4 chunk of ``inflated_bytes`` zeros (1.1 MB for 256 MB) whose frame states no
    size and whose record claims 100 bytes: mcap inflates an lz4 frame whole."""
    import lz4.frame

    real_compress = lz4.frame.compress
    lz4.frame.compress = lambda data, **_: real_compress(data, store_size=False)
    try:
        with open(path, "wb") as file:
            writer, channel = _writer(file, "lz4", 2 * inflated_bytes)
            writer.add_message(channel, log_time=1, data=bytes(inflated_bytes), publish_time=1)
            writer.finish()
    finally:
        lz4.frame.compress = real_compress
    from mcap.reader import SeekingReader

    with open(path, "rb") as file:
        (chunk,) = SeekingReader(file).get_summary().chunk_indexes
    data = path.read_bytes()
    stated = struct.pack("<Q", chunk.uncompressed_size)  # the message record and its header
    assert chunk.uncompressed_size > inflated_bytes and stated in data
    path.write_bytes(data.replace(stated, struct.pack("<Q", 100), 1))  # the chunk record's
    return path


def overlapping_chunks(path: Path, chunks: int, chunk_bytes: int) -> Path:
    """``chunks`` zstd chunks of ``chunk_bytes`` zeros that each start early and end late: a
    merge by log time (mcap's indexed reading) holds them all inflated at once."""
    with open(path, "wb") as file:
        writer, channel = _writer(file, "zstd", chunk_bytes)
        for index in range(chunks):
            writer.add_message(channel, log_time=index + 1, data=b"", publish_time=1)
            writer.add_message(channel, log_time=10**12, data=bytes(chunk_bytes), publish_time=1)
        writer.finish()
    return path
