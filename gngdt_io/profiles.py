"""The one reader of parameter files (TOML): `gngdt learn --params`, `gngdt run --params`,
`gngdt segment --params` and evaluation all read profiles here.

A profile only overrides what `gngdt.core.parameters` declares. Tables: ``[gngdt]`` (`GNGDT`
constructor arguments; ``lambda`` means ``lambda_``), ``[learner]`` (`LearnerOptions`),
``[segmentation]`` (`SegmentationParams`), ``[tracker]`` (`TrackerParams`: the camera tracking
of ``track``) and ``[frames]`` (`FrameSchedule`: a sensor profile's frame schedule; with it, the
learner learns through `StreamLearner`). Keys at the top level count
as ``[gngdt]`` or ``[learner]`` keys by their name. The steps per later frame of a stream are
``[learner] samples_per_frame``; ``[frames] steps_per_frame`` is accepted as its other name.
Anything else is an error naming the file and the key. `Profile.sources` says where every
effective value came from; `format_parameters` prints them (``gngdt learn --print-params``).
"""

from __future__ import annotations

import inspect
import tomllib
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

from gngdt.core.gas.model import GNGDT
from gngdt.core.learner.frame_learner import (
    LEARNER_MODEL_DEFAULTS,
    LEARNER_WORLD_DEFAULTS,
    LearnerConfig,
    LearnerOptions,
)
from gngdt.core.learner.stream_learner import FrameSchedule
from gngdt.core.odometry.map_odometry import TrackerParams
from gngdt.core.segmentation.network import SegmentationParams

#: the sensor profile `gngdt segment` uses without ``--params``, a file of the installed
#: ``gngdt.config`` package (the repository's config/)
DEFAULT_SENSOR_PROFILE = "kinect.toml"
#: where a value comes from when no file or option sets it
LEARNER_DEFAULT = "the learner's default"
DEFAULT = "default"
TABLES = ("gngdt", "learner", "segmentation", "tracker", "frames")
#: the constraint of samples_per_frame, for its other name in [frames]
_STEPS = next(item.metadata["constraint"] for item in fields(LearnerOptions)
              if item.name == "samples_per_frame")


@dataclass(frozen=True)
class Profile:
    """Effective parameters and where each came from."""

    config: LearnerConfig
    #: "table.key" -> a file path, a command-line option or a default
    sources: dict[str, str]
    #: the file read (None: the defaults alone)
    path: Path | None = None

    def with_overrides(self, model: dict[str, Any], options: dict[str, Any],
                       source: str) -> Profile:
        """This profile with ``model`` and ``options`` values (None: not given) overriding it."""
        model = {name: value for name, value in model.items() if value is not None}
        options = {name: value for name, value in options.items() if value is not None}
        if not model and not options:
            return self
        config = replace(self.config, model={**self.config.model, **model},
                         options=replace(self.config.options, **options))
        config = replace(config)  # checks the options together (a track with a schedule)
        if config.schedule is not None and "samples_per_frame" in options:
            config = replace(config, schedule=replace(
                config.schedule, steps_per_frame=config.options.samples_per_frame))
        _check_model(config.model, source)
        sources = dict(self.sources)
        sources.update({f"gngdt.{name}": source for name in model})
        sources.update({f"learner.{name}": source for name in options})
        return Profile(config, sources, self.path)

    def model_value(self, name: str) -> Any:
        """A GNG-DT parameter's effective value: set, or the constructor's default."""
        return self.config.model.get(name, _signature_defaults()[name])

    def segmenter_schedule(self) -> FrameSchedule:
        """The frame schedule of `gngdt segment`: the profile's, else the defaults with the
        profile's steps per frame."""
        return self.config.schedule or FrameSchedule(
            steps_per_frame=self.config.options.samples_per_frame)

    def as_dict(self) -> dict[str, Any]:
        """The parameters as the profile's tables (for reports)."""
        config = self.config
        return {"profile": str(self.path), "gngdt": dict(config.model),
                "learner": asdict(config.options),
                "segmentation": asdict(config.segmentation),
                "tracker": asdict(config.tracker),
                "frames": asdict(self.segmenter_schedule())}


def model_parameter_names() -> set[str]:
    """Names of the ``GNGDT`` constructor arguments a params file may set (the seed is the
    learner option ``seed``, so that one key sets it)."""
    return {name for name in inspect.signature(GNGDT.__init__).parameters
            if name not in ("self", "random_state")}


def read_toml(path: Path) -> dict[str, Any]:
    """The TOML document in ``path``; ValueError naming the file when it cannot be read or
    parsed."""
    try:
        with open(path, "rb") as file:
            return tomllib.load(file)
    except OSError as error:
        raise ValueError(f"{path}: {error.strerror or error}") from error
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: invalid TOML: {error}") from error


def default_sensor_profile() -> Path:
    """Where the default sensor profile is installed (config/kinect.toml in a checkout)."""
    import gngdt.config

    # a namespace package in an editable install: its folders, not a __file__
    for folder in gngdt.config.__path__:
        candidate = Path(folder) / DEFAULT_SENSOR_PROFILE
        if candidate.is_file():
            return candidate
    raise ValueError(f"the default sensor profile {DEFAULT_SENSOR_PROFILE} is not installed "
                     f"with gngdt_config ({list(gngdt.config.__path__)}); give --params")


def load_profile(path: Path | None, base_model: dict[str, Any] | None = None) -> Profile:
    """The parameters of the file ``path`` over the defaults (None: the defaults alone).

    base_model: GNG-DT arguments the file overrides (default: the learner's profile,
    `LEARNER_MODEL_DEFAULTS`; ``{}``: the paper's defaults, as `gngdt segment` learns).
    Raises ValueError naming the file and the key.
    """
    base = dict(LEARNER_MODEL_DEFAULTS if base_model is None else base_model)
    base_source = LEARNER_DEFAULT if base_model is None else DEFAULT
    tables = _tables(read_toml(path), path) if path is not None else {name: {} for name in TABLES}
    try:
        model = {**base, **tables["gngdt"]}
        options = LearnerOptions.from_dict(tables["learner"])
        segmentation = SegmentationParams.from_dict(tables["segmentation"])
        tracker = TrackerParams.from_dict(tables["tracker"])
        schedule = None
        if path is not None and tables["frames"] is not None:
            schedule = FrameSchedule.from_dict(
                {**tables["frames"], "steps_per_frame": options.samples_per_frame})
        config = LearnerConfig(model, options, segmentation, schedule, tracker)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path}: {error}") from error
    _check_model(model, str(path))
    sources = {f"gngdt.{name}": base_source for name in base}
    for table, values in tables.items():
        sources.update({f"{table}.{key}": str(path) for key in values or {}})
    return Profile(config, sources, path)


def load_sensor_profile(path: Path | None = None) -> Profile:
    """A sensor profile for segmenting frames (`gngdt segment`, `gngdt eval segmentation`): the
    file ``path``, else the default one, over the paper's GNG-DT defaults."""
    return load_profile(path or default_sensor_profile(), base_model={})


def _tables(document: dict[str, Any], path: Path) -> dict[str, dict[str, Any] | None]:
    """The document's keys sorted into `TABLES` (``frames`` None when the file has no such
    table); ValueError naming the file and key for anything unknown. Keys of ``[gngdt]``,
    ``[learner]`` and the top level are sorted by their names (either table takes either)."""
    model_names = model_parameter_names()
    option_names = {item.name for item in fields(LearnerOptions)}
    tables: dict[str, dict[str, Any] | None] = {name: {} for name in TABLES}
    tables["frames"] = None
    flat: dict[str, Any] = {}
    for key, value in document.items():
        if isinstance(value, dict) and key in ("gngdt", "learner"):
            flat.update(value)
        elif isinstance(value, dict) and key in TABLES:
            tables[key] = {**(tables[key] or {}), **value}
        elif isinstance(value, dict):
            raise ValueError(f"{path}: unknown table [{key}] (known: "
                             f"{', '.join(f'[{name}]' for name in TABLES)})")
        else:
            flat[key] = value
    for key, value in flat.items():
        name = "lambda_" if key == "lambda" else key
        if name in model_names:
            tables["gngdt"][name] = value
        elif name in option_names:
            tables["learner"][name] = value
        else:
            known = ", ".join(sorted(model_names | option_names))
            raise ValueError(f"{path}: unknown key {key!r} (known: {known})")
    frames = tables["frames"]
    if frames is not None and "steps_per_frame" in frames:  # the other name of samples_per_frame
        steps = frames.pop("steps_per_frame")
        try:
            _STEPS.check("[frames] steps_per_frame", steps)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None
        learner = tables["learner"]
        if learner.get("samples_per_frame", steps) != steps:
            raise ValueError(f"{path}: [frames] steps_per_frame = {steps} contradicts "
                             f"samples_per_frame = {learner['samples_per_frame']} (one setting: "
                             "keep [learner] samples_per_frame)")
        learner["samples_per_frame"] = steps
    return tables


def _check_model(model: dict[str, Any], source: str) -> None:
    try:
        GNGDT(**model).check_params()
    except (TypeError, ValueError) as error:
        raise ValueError(f"{source}: {error}") from error


def format_parameters(profile: Profile) -> str:
    """Every effective parameter as TOML tables, each with where it came from."""
    config = profile.config
    tables: dict[str, dict[str, Any]] = {
        "gngdt": {**_signature_defaults(), **config.model},
        "learner": asdict(config.options),
        "segmentation": asdict(config.segmentation),
        "tracker": asdict(config.tracker),
    }
    if config.schedule is not None:
        tables["frames"] = asdict(config.schedule)
    lines = []
    for table, values in tables.items():
        lines.append(f"[{table}]")
        width = max(len(f"{key} = {_toml(value)}") + 2 for key, value in values.items())
        for key, value in values.items():
            setting = f"{key} = {_toml(value)}" if value is not None else f"# {key} unset"
            source = profile.sources.get(f"{table}.{key}", DEFAULT)
            if table == "frames" and key == "steps_per_frame":
                source = "[learner] samples_per_frame"
            if table == "gngdt" and key in LEARNER_WORLD_DEFAULTS and key not in config.model:
                source += (f"; a map in a fixed frame (posed or tracked clouds): "
                           f"{_toml(LEARNER_WORLD_DEFAULTS[key])}, the learner's default")
            lines.append(f"{setting:<{width}}  # {source}")
        lines.append("")
    return "\n".join(lines)


def _signature_defaults() -> dict[str, Any]:
    return {name: parameter.default
            for name, parameter in inspect.signature(GNGDT.__init__).parameters.items()
            if name in model_parameter_names()}


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml(item) for item in value) + "]"
    return repr(value)
