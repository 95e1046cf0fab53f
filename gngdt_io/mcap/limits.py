"""Reading an MCAP file within bounds: :class:`ReadLimits`, the chunk check that refuses a file
whose chunks would inflate beyond them, and its messages streamed in file order."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import IO, Any

from gngdt.io.errors import RecordingError

__all__ = ["ReadLimits", "check_chunks", "open_messages"]

logger = logging.getLogger(__name__)


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
    stream: IO[bytes], max_record_bytes: int = ReadLimits.max_chunk_bytes
) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) in file order, streamed one chunk at a time, so that a damaged
    file still delivers everything before the damage and memory stays within one chunk.

    Not mcap's log-time merge of the chunk index: it inflates every chunk whose time range
    overlaps the next message's time before yielding it, so chunks that each start early and end
    late are all held at once (12 such chunks in 18 kB held 480 MB). MCAP writers (gngdt's,
    rosbag2's) write messages in log-time order, and frames are paired by their stamps anyway.
    Records larger than ``max_record_bytes`` are refused (mcap raises).
    """
    from mcap.reader import NonSeekingReader

    return NonSeekingReader(stream, validate_crcs=True, record_size_limit=max_record_bytes
                            ).iter_messages(log_time_order=False)


def check_chunks(stream: IO[bytes], path: Path, max_chunk_bytes: int) -> None:
    """Refuse (``RecordingError``) a file holding a chunk that would inflate beyond
    ``max_chunk_bytes``, by the sizes its record and its zstd frame declare (an 8 kB chunk of
    zeros can declare 256 MB) or, for lz4, by inflating at most that much of it, before mcap
    inflates any chunk. Reads the file once, a chunk at a time;
    damage is left for the reading itself to report, after the frames before it."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    offset = 0
    try:
        reader = StreamReader(stream, emit_chunks=True, record_size_limit=max_chunk_bytes)
        for record in reader.records:
            if isinstance(record, Chunk):
                declared = max(record.uncompressed_size, _inflated_size(record, max_chunk_bytes))
                if declared > max_chunk_bytes:
                    raise RecordingError(
                        path, None, f"a {record.compression or 'raw'} chunk of "
                        f"{len(record.data)} bytes (at log time {record.message_start_time}) "
                        f"inflates to {declared} bytes or more, beyond the limit of "
                        f"{max_chunk_bytes} (--max-chunk-mb)")
            offset += 1
    except RecordingError:
        raise
    except Exception as error:  # damage: the reading itself reports it, with its place
        logger.debug("%s: chunk check stopped at record %d: %s", path, offset, error)
    finally:
        stream.seek(0)


def _inflated_size(chunk: Any, limit: int) -> int:
    """What the chunk inflates to, as far as matters before mcap inflates it (0: unknown).

    zstd: the size its frame header states (mcap inflates a frame that states none into at most
    the record's ``uncompressed_size``). lz4: mcap inflates the frame whole, whatever any header
    says (1 MB of lz4 is 256 MB of zeros), so the frame is inflated here, at most ``limit + 1``
    bytes of it, and counted.
    """
    try:
        if chunk.compression == "zstd":
            import zstandard

            return max(int(zstandard.frame_content_size(chunk.data)), 0)
        if chunk.compression == "lz4":
            import lz4.frame

            decompressor = lz4.frame.LZ4FrameDecompressor()
            return len(decompressor.decompress(chunk.data, max_length=limit + 1))
    except Exception:  # an unreadable frame fails decompression later, with its place
        return 0
    return 0
