"""Sensor profiles for frame segmentation: a TOML file with the model, segmentation and frame
schedule parameters of `gngdt_core.frame_segmenter.FrameSegmenter`.

Tables: ``[gngdt]`` (GNGDT constructor arguments; ``lambda`` means ``lambda_``; flat keys at the
top level count as ``[gngdt]`` too, as in ``gngdt learn --params``), ``[segmentation]``
(`SegmentationParams`), ``[frames]`` (`FrameSchedule`). ``[learner]`` and flat learner options
belong to ``gngdt learn`` (which reads the same profile) and are ignored here. Anything else is
an error naming the file and the key. Keys left out take the classes' defaults.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from gngdt_core.frame_segmenter import FrameSchedule, FrameSegmenter
from gngdt_core.segmentation import SegmentationParams

#: the sensor profile used without ``--params``, a file of the installed ``gngdt_config``
#: package (the repository's config/)
DEFAULT_PROFILE_NAME = "kinect.toml"


def default_profile() -> Path:
    """Where the default sensor profile is installed (config/kinect.toml in a checkout)."""
    import gngdt_config

    # a namespace package in an editable install: its folders, not a __file__
    for folder in gngdt_config.__path__:
        candidate = Path(folder) / DEFAULT_PROFILE_NAME
        if candidate.is_file():
            return candidate
    raise ValueError(f"the default sensor profile {DEFAULT_PROFILE_NAME} is not installed "
                     f"with gngdt_config ({list(gngdt_config.__path__)}); give --params")


#: tables of a profile that belong to other commands
IGNORED_TABLES = ("learner",)


@dataclass(frozen=True)
class SegmenterProfile:
    """Everything a `FrameSegmenter` is built from, and where it came from."""

    model: dict[str, Any]
    segmentation: SegmentationParams
    schedule: FrameSchedule
    #: the TOML file read
    source: str

    def segmenter(self, random_state: int | None = 0) -> FrameSegmenter:
        return FrameSegmenter(self.model, self.segmentation, self.schedule, random_state)

    def as_dict(self) -> dict[str, Any]:
        """The parameters as the profile's TOML tables (for reports)."""
        return {"profile": self.source, "gngdt": dict(self.model),
                "segmentation": asdict(self.segmentation), "frames": asdict(self.schedule)}


def load_profile(path: str | Path | None = None) -> SegmenterProfile:
    """The profile in ``path``, else the default sensor profile (`default_profile`). ValueError
    naming the file and key for unknown tables or keys and invalid values."""
    from services.learner import LearnerOptions, model_parameter_names, read_toml

    path = Path(path) if path is not None else default_profile()
    document = read_toml(path, str(path))
    tables: dict[str, dict[str, Any]] = {"gngdt": {}, "segmentation": {}, "frames": {}}
    learner_options = {item.name for item in fields(LearnerOptions)}
    for key, value in document.items():
        if key in tables and isinstance(value, dict):
            tables[key].update(value)
        elif key in IGNORED_TABLES and isinstance(value, dict):
            continue
        elif isinstance(value, dict):
            raise ValueError(f"{path}: unknown table [{key}] (known: [gngdt], [segmentation], "
                             f"[frames]; [learner] is gngdt learn's)")
        elif key not in learner_options:
            tables["gngdt"][key] = value
    model = {("lambda_" if key == "lambda" else key): value
             for key, value in tables["gngdt"].items()}
    known = model_parameter_names()
    unknown = sorted(set(model) - known)
    if unknown:
        raise ValueError(f"{path}: unknown [gngdt] key(s) {unknown} (known: {sorted(known)})")
    try:
        profile = SegmenterProfile(model, SegmentationParams.from_dict(tables["segmentation"]),
                                   FrameSchedule.from_dict(tables["frames"]), str(path))
        profile.segmenter()  # validates the model parameters
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path}: {error}") from error
    return profile
