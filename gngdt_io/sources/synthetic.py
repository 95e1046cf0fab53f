"""Synthetic scenes of the virtual Kinect as a frame source: ``synth:<scene>[:<frames>]``
(`gngdt.io.synth`), e.g. ``synth:tabletop_walk:240``. Frame names: the index as 6 digits."""

from __future__ import annotations

from collections.abc import Iterator

from gngdt.io.frame import Frame
from gngdt.io.sources.base import FrameSource

#: frames of a synthetic source when the spec does not say
DEFAULT_FRAMES = 30


class SyntheticSource(FrameSource):
    """Frames rendered from one of the virtual Kinect's scenes (640x480, seed 0)."""

    format = "synth"
    scheme = "synth"

    def __init__(self, spec: str) -> None:
        from gngdt.io.synth.render import SCENES

        _, _, rest = spec.partition(":")
        scene, _, count = rest.partition(":")
        if scene not in SCENES:
            raise ValueError(f"{spec}: unknown scene {scene!r}; known: {', '.join(SCENES)}")
        try:
            self.frame_count = int(count) if count else DEFAULT_FRAMES
        except ValueError:
            raise ValueError(f"{spec}: frames must be a number, got {count!r}") from None
        if self.frame_count < 1:
            raise ValueError(f"{spec}: frames must be >= 1, got {self.frame_count}")
        self.scene = scene
        super().__init__(spec, "the virtual Kinect's intrinsics")

    def frames(self) -> Iterator[tuple[str, Frame]]:
        from gngdt.io.synth.render import render_scene

        for frame in render_scene(self.scene, self.frame_count):
            yield f"{frame.index:06d}", frame

    def describe(self) -> str:
        return f"the synthetic scene {self.scene!r} ({self.frame_count} frames)"
