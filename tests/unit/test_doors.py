"""The house's doors: a new frame source or logger output is one module plus one registration
line. A toy of each, registered the way a real one is, goes through the real code paths."""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator

import numpy as np
import pytest

from gngdt.io import outputs, sources
from gngdt.io.frame import CameraIntrinsics, Frame
from gngdt.io.outputs import Output, StreamSample
from gngdt.io.sources import FrameSource, open_source
from gngdt.schemas.status import encode_stream_end
from gngdt.schemas.wire import FrameStamp


class ToySource(FrameSource):
    """``toy:<frames>``: a grey plane one metre away, frame after frame."""

    format = "toy"
    scheme = "toy"

    def __init__(self, spec: str) -> None:
        self.count = int(spec.split(":", 1)[1])
        super().__init__(spec, "made up")

    def frames(self) -> Iterator[tuple[str, Frame]]:
        for index in range(self.count):
            color = np.full((24, 32, 3), 128, np.uint8)
            depth = np.full((24, 32), 1000, np.uint16)
            yield f"toy{index}", Frame(index, 1_000_000 * index, color, depth,
                                       CameraIntrinsics(32, 24, 30.0, 30.0, 16.0, 12.0))


class ToyOutput(Output):
    """``--toy``: keeps the streams of every sample it is given."""

    def __init__(self) -> None:
        self.streams: list[str] = []
        self.closed = False

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--toy", action="store_true", help="the toy output")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ToyOutput | None:
        return cls() if args.toy else None

    def describe(self) -> str:
        return "toy"

    def write(self, sample: StreamSample) -> None:
        self.streams.append(sample.stream)

    def close(self) -> None:
        self.closed = True


def test_a_new_source_is_one_class_and_one_registration_line(monkeypatch) -> None:
    from gngdt.io.deproject import CloudOptions, FrameToCloud
    from gngdt.io.segment_frames import organized_frames

    monkeypatch.setattr(sources, "SOURCE_TYPES", (ToySource, *sources.SOURCE_TYPES))
    source = open_source("toy:3")
    assert isinstance(source, ToySource) and source.check() == 3
    # capture's frame-to-cloud and segment's deprojection take it as any other source
    positions, _ = FrameToCloud(CloudOptions())(next(source.frames())[1])
    assert len(positions) == 24 * 32 and np.allclose(positions[:, 2], 1.0)
    names = [name for name, _, points, _ in organized_frames(source)]
    assert names == ["toy0", "toy1", "toy2"]


def test_a_new_output_is_one_class_and_one_registration_line(monkeypatch, tmp_path) -> None:
    from gngdt.services.logger import add_arguments, build_outputs
    from gngdt.services.logger.cameras import Cameras
    from gngdt.services.logger.dispatch import Dispatcher

    monkeypatch.setattr(outputs, "OUTPUTS", (*outputs.OUTPUTS, ToyOutput))
    parser = argparse.ArgumentParser()
    add_arguments(parser)  # the logger offers the new output's options ...
    args = parser.parse_args(["--toy", "--save", str(tmp_path / "x.rrd")])
    made = build_outputs(args)  # ... and builds it beside the others
    assert [type(output).__name__ for output in made] == ["RerunOutput", "ToyOutput"]
    toy = made[1]
    dispatcher = Dispatcher(made, Cameras())
    end = encode_stream_end(timestamp_ns=time.time_ns(), frames_sent=1, last_frame_sequence=0)
    dispatcher.handle("gngdt/camera/eos", end.SerializeToString(),
                      FrameStamp(0, time.time_ns()).to_attachment())
    assert toy.streams == ["eos"] and dispatcher.cameras.names() == ["camera"]
    for output in made:
        output.close()
    assert toy.closed and (tmp_path / "x.rrd").is_file()


def test_an_unregistered_scheme_is_not_guessed() -> None:
    from gngdt.io.errors import RecordingError

    with pytest.raises(RecordingError, match="toy:2: no such file or folder"):
        open_source("toy:2")
