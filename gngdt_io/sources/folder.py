"""Folders of RGB-D images as frame sources, in a layout ``gngdt record images`` reads
(`gngdt.io.images`: ``tum``, ``pcl-tiff``, ``redwood``; other files and folders in it, such as a
labelled set's ``label/``, are ignored). Frame names: the colour image's file stem.

A folder without ``camera.json`` (and no ``--camera-json`` given) is read with its layout's
default intrinsics; that is warned about, naming the values assumed, and the source says so in
``camera_note``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from gngdt.io.errors import RecordingError
from gngdt.io.frame import Frame
from gngdt.io.images import (
    DEFAULT_CAMERAS,
    FORMATS,
    camera_assumptions,
    iter_image_frames,
    load_camera,
)
from gngdt.io.sources.base import FrameSource, SourceOptions

log = logging.getLogger(__name__)


class ImageFolderSource(FrameSource):
    """A folder of colour and depth images in one of `FORMATS`."""

    def __init__(self, path: Path, layout: str, options: SourceOptions) -> None:
        if layout not in FORMATS:
            raise ValueError(f"image layout must be one of {FORMATS}, got {layout!r}")
        self.format = layout
        self.camera_json = options.camera_json
        self.depth_scale = options.depth_scale
        if self.camera_json is not None:
            load_camera(path, layout, self.camera_json)  # fail now on a bad file
            note = str(self.camera_json)
        elif (path / "camera.json").is_file():
            load_camera(path, layout)
            note = str(path / "camera.json")
        else:
            camera = DEFAULT_CAMERAS[layout]
            note = (f"ASSUMED: {path / 'camera.json'} is missing, so the {layout} defaults are "
                    f"used: fx={camera.fx} fy={camera.fy} cx={camera.cx} cy={camera.cy} px "
                    "(for 640x480, scaled to the images' size), "
                    f"depth_scale={camera.depth_scale:g} units/m. Wrong intrinsics bend every "
                    "surface; add camera.json or pass --camera-json")
        super().__init__(path, note)
        self.assumptions = camera_assumptions(path, layout, self.camera_json, self.depth_scale)
        for assumption in self.assumptions:
            log.warning("%s", assumption)

    @staticmethod
    def accepts(path: Path) -> bool:
        return path.is_dir()

    def frames(self) -> Iterator[tuple[str, Frame]]:
        camera = load_camera(self.path, self.format, self.camera_json)
        if self.depth_scale is not None:
            camera = replace(camera, depth_scale=self.depth_scale)
        names: dict[str, str] = {}
        for frame in iter_image_frames(self.path, self.format, camera=camera):
            color_path = str(frame.color_path)
            name = Path(color_path).stem
            if name in names:
                raise RecordingError(color_path, frame.index,
                                     f"two colour images have the name {name!r} "
                                     f"(also {names[name]}); outputs would collide")
            names[name] = color_path
            yield name, frame
