"""The output interface the logger drives: one object per destination of gngdt's streams.

An output takes the samples of ``gngdt/**`` in one of two ways:

- *raw* outputs (``raw = True``: recorders, live servers) get every sample on zenoh's thread,
  as it arrives, in `receive`; they must never block there (queue and write from a thread);
- the others (viewers: rerun) get the samples from the logger's loop in `write`, after its
  inbox has kept only the newest image and cloud of each camera when the logger fell behind.

Both get `tick` on every loop (flush, bounds) and `close` at the end. A malformed sample raises
ValueError from `write`; the logger counts and skips it. Options come from the command line:
`add_arguments` declares them (no heavy import: ``gngdt --help`` stays fast), `check_args` says
what cannot work before any output opens, and `from_args` builds the output, or None when its
options do not ask for it.
"""

from __future__ import annotations

import argparse
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, ClassVar

from gngdt.schemas.wire import FrameStamp, topic

if TYPE_CHECKING:
    import zenoh

    from gngdt.schemas import gngdt_pb2
    from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo


@dataclass(frozen=True)
class StreamSample:
    """One sample of one camera's stream: ``gngdt/<camera>/<stream>``. The learner's status,
    a topology and the end of stream are parsed once, when first read
    (ValueError when malformed), for the logger's bookkeeping and every output alike."""

    camera: str
    #: ``color``, ``points``, ``learner/status``, ...
    stream: str
    stamp: FrameStamp
    payload: bytes

    @property
    def key(self) -> str:
        return topic(self.camera, self.stream)

    @cached_property
    def status(self) -> LearnerStatusInfo:
        """The ``learner/status`` sample, decoded."""
        from gngdt.schemas.status import decode_status

        return decode_status(self.payload)

    @cached_property
    def topology(self) -> gngdt_pb2.Topology:
        """The ``topology`` sample's ``gngdt.Topology``, parsed but not validated (the logger
        reads its settled flag, an output decodes it within its own limits)."""
        from gngdt.schemas import gngdt_pb2
        from gngdt.schemas.messages import parse_message

        return parse_message(gngdt_pb2.Topology, self.payload)

    @cached_property
    def stream_end(self) -> StreamEndInfo:
        """The ``eos`` sample, decoded."""
        from gngdt.schemas.status import decode_stream_end

        return decode_stream_end(self.payload)


def split_bind(address: str, default_port: int) -> tuple[str, int]:
    """``(host, port)`` of ``HOST[:PORT]`` (``[::1]:8765`` for IPv6); ValueError naming it."""
    host, port = address, default_port
    if address.startswith("["):
        host, _, rest = address[1:].partition("]")
        if rest and not rest.startswith(":"):
            raise ValueError(f"--bind {address!r}: expected [IPv6]:PORT")
        port_text = rest[1:]
    elif address.count(":") == 1:
        host, _, port_text = address.partition(":")
    else:  # a bare IPv4 address, host name or IPv6 address
        port_text = ""
    if port_text:
        if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise ValueError(f"--bind {address!r}: the port must be 0..65535")
        port = int(port_text)
    if not host:
        raise ValueError(f"--bind {address!r}: no host (e.g. 127.0.0.1:{default_port})")
    return host, port


def split_key(key: str) -> tuple[str, str] | None:
    """``(camera, stream)`` of ``gngdt/<camera>/<stream>``, or None for any other key."""
    parts = key.split("/", 2)
    if len(parts) < 3 or parts[0] != "gngdt" or not parts[1] or not parts[2]:
        return None
    return parts[1], parts[2]


class Output(ABC):
    """Where the logger's streams go (see the module's docstring)."""

    #: gets every sample on zenoh's thread (`receive`) instead of the loop's (`write`)
    raw: ClassVar[bool] = False

    @classmethod
    @abstractmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        """Declare this output's command-line options."""

    @classmethod
    def check_args(cls, args: argparse.Namespace) -> None:
        """ValueError/OSError when the options cannot work (a port in use), said before any
        output is opened."""
        return None

    @classmethod
    @abstractmethod
    def from_args(cls, args: argparse.Namespace) -> Output | None:
        """The output the options ask for, or None. ValueError/OSError: a clear error."""

    @abstractmethod
    def describe(self) -> str:
        """Where the streams go, for people (``logging to runs/x.rrd``)."""

    def receive(self, sample: zenoh.Sample) -> None:
        """A raw output's sample, on zenoh's thread (never blocks)."""
        raise NotImplementedError

    def write(self, sample: StreamSample) -> None:
        """A sample from the logger's loop; ValueError when it is malformed."""
        raise NotImplementedError

    def wants(self, camera: str, stream: str, sequence: int) -> bool:
        """Whether frame ``sequence`` of a thinned stream (images, clouds) would be written:
        asked on zenoh's thread before the payload is copied (default: always)."""
        return True

    def cameras_changed(self, cameras: list[str]) -> None:
        """The logger now knows these cameras (a new one came)."""
        return None

    def tick(self) -> None:
        """Called on every turn of the logger's loop."""
        return None

    def stopped_early(self) -> str:
        """Why this output stopped writing before the end (``""``: it did not)."""
        return ""

    @abstractmethod
    def close(self) -> None:
        """Finish the output (files complete and readable)."""
