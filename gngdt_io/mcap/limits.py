"""Reading an MCAP file within bounds: :class:`ReadLimits`, and its messages streamed in file
order, each chunk checked before it is inflated beyond them."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import IO, Any

from gngdt.io.errors import RecordingError

__all__ = ["ReadLimits", "open_messages"]


@dataclass(frozen=True)
class ReadLimits:
    """What reading a recording may cost, however the file is made: a few kilobytes must not
    cost gigabytes or minutes. Each is checked before the memory is spent.

    max_frame_pixels: largest image (width x height); default 4096 x 2160.
    max_chunk_bytes: largest MCAP chunk once decompressed (and largest record).
    max_held_bytes: images held while they wait for their partner or for a calibration.
    max_transform_samples: transform samples read for camera poses (at most 64 bytes each kept;
    ~30-45 s to read a million); the rest are not read.
    """

    max_frame_pixels: int = 4096 * 2160
    max_chunk_bytes: int = 64 * 1024 * 1024
    max_held_bytes: int = 256 * 1024 * 1024
    max_transform_samples: int = 1_000_000

    def __post_init__(self) -> None:
        for item in fields(self):
            if getattr(self, item.name) <= 0:
                raise ValueError(f"{item.name} must be positive, got {getattr(self, item.name)}")


def open_messages(
    stream: IO[bytes], path: Path, max_chunk_bytes: int = ReadLimits.max_chunk_bytes
) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) in file order, streamed one chunk at a time, so that a damaged
    file still delivers everything before the damage and memory stays within one chunk.

    Each chunk is checked before it is inflated beyond ``max_chunk_bytes``: one whose record or
    zstd frame declares more (an 8 kB chunk of zeros can declare 256 MB), or whose lz4 frame
    inflates to more (mcap inflates an lz4 frame whole, whatever any header says), raises
    ``RecordingError`` naming ``path``, after the messages before it. An lz4 chunk is inflated
    once, by that check, and its records read from what it gave.

    Not mcap's log-time merge of the chunk index: it inflates every chunk whose time range
    overlaps the next message's time before yielding it, so chunks that each start early and end
    late are all held at once (12 such chunks in 18 kB held 480 MB). MCAP writers (gngdt's,
    rosbag2's) write messages in log-time order, and frames are paired by their stamps anyway.
    Records larger than ``max_chunk_bytes`` are refused (mcap raises), and so is damage: mcap's
    errors (truncation, CRC, a message before its channel) end the iteration.
    """
    from mcap.exceptions import McapError
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    reader = StreamReader(stream, emit_chunks=True, validate_crcs=True,
                          record_size_limit=max_chunk_bytes)
    for record in reader.records:
        records = (breakup_chunk(_checked(record, path, max_chunk_bytes), validate_crc=True)
                   if isinstance(record, Chunk) else (record,))
        for item in records:  # as mcap's NonSeekingReader.iter_messages
            if isinstance(item, Schema):
                schemas[item.id] = item
            elif isinstance(item, Channel):
                if item.schema_id != 0 and item.schema_id not in schemas:
                    raise McapError(f"no schema record found with id {item.schema_id}")
                channels[item.id] = item
            elif isinstance(item, Message):
                channel = channels.get(item.channel_id)
                if channel is None:
                    raise McapError(f"no channel record found with id {item.channel_id}")
                yield (schemas[channel.schema_id] if channel.schema_id else None), channel, item


def _checked(chunk: Any, path: Path, limit: int) -> Any:
    """``chunk``, or for lz4 the same chunk already inflated, once it is known not to inflate
    beyond ``limit`` bytes; ``RecordingError`` if it would.

    zstd: the size its frame header states (mcap inflates a frame that states none into at most
    the record's ``uncompressed_size``). lz4: mcap inflates the frame whole, whatever any header
    says (1 MB of lz4 is 256 MB of zeros), so the frame is inflated here, at most ``limit + 1``
    bytes of it. An unreadable frame is left for mcap to fail on, with its place.
    """
    inflated = None
    declared = chunk.uncompressed_size
    try:
        if chunk.compression == "zstd":
            import zstandard

            declared = max(declared, int(zstandard.frame_content_size(chunk.data)))
        elif chunk.compression == "lz4":
            import lz4.frame

            decompressor = lz4.frame.LZ4FrameDecompressor()
            inflated = decompressor.decompress(chunk.data, max_length=limit + 1)
            declared = max(declared, len(inflated))
            if not decompressor.eof or decompressor.unused_data:  # left to mcap, as it is
                inflated = None
    except Exception:  # an unreadable frame fails decompression in mcap, with its place
        inflated = None
    if declared > limit:
        raise RecordingError(
            path, None, f"a {chunk.compression or 'raw'} chunk of {len(chunk.data)} bytes (at "
            f"log time {chunk.message_start_time}) inflates to {declared} bytes or more, beyond "
            f"the limit of {limit} (--max-chunk-mb)")
    return chunk if inflated is None else replace(chunk, compression="", data=inflated)
