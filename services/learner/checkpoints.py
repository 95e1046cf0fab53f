"""The learner's checkpoints: its network, counters and frame (and with ``--track`` its camera
tracker: pose, motion, plane memory, as ``tracker_*`` arrays) saved to a file and resumed from
it (`gngdt.io.checkpoints` writes and checks the file)."""

from __future__ import annotations

import json
import logging
import math
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.core.clustering import COL, POS
from gngdt.core.gas.model import GNGDT
from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig
from gngdt.core.learner.results import Counters
from gngdt.core.odometry.pose_checks import points_beyond_workspace
from gngdt.io.checkpoints import (
    CheckpointError,
    load_checkpoint,
    remove_stale_temporaries,
    save_checkpoint,
)

log = logging.getLogger(__name__)

#: largest counter a checkpoint may hold: a quarter of the status's and the checkpoint's
#: 64-bit range, so a resumed learner counts on for ever without overflowing
MAX_LOADED_COUNTER = 2**62
#: the tracker's arrays in a checkpoint's state
TRACKER_PREFIX = "tracker_"


def save(learner: FrameLearner, path: Path) -> bool:
    """Checkpoint to ``path``; a failed write (disk full, permissions) is logged, not fatal:
    the learner goes on and the previous checkpoint, replaced atomically, stays intact."""
    counters = {item.name: getattr(learner.counters, item.name) for item in fields(Counters)}
    state = learner.model.get_state()
    if learner.tracking is not None:
        state.update({f"{TRACKER_PREFIX}{key}": value
                      for key, value in learner.tracking.get_state().items()})
    try:
        save_checkpoint(path, state,
                        {"camera": learner.camera, "counters": counters,
                         "frame_id": learner.frame_id})
    except (OSError, ValueError, OverflowError) as error:  # a full disk; a state out of range
        log.error("checkpoint %s not written: %s", path, error)
        return False
    log.debug("checkpoint %s: %d nodes, %d steps", path, learner.model.n_nodes_,
              learner.model.n_steps_)
    return True


def resume(path: Path, camera: str, config: LearnerConfig) -> FrameLearner:
    """A learner restored from ``path`` (raises ``CheckpointError`` when it is corrupt)."""
    state, metadata = load_checkpoint(path)
    saved_camera = metadata.get("camera", camera)
    if saved_camera != camera:
        raise CheckpointError(
            f"checkpoint {path} holds what camera {saved_camera!r} learned, not {camera!r}; "
            f"resume it with --cam {saved_camera} or give this camera its own --checkpoint")
    try:
        model = GNGDT.from_state(state)
    except (KeyError, ValueError, TypeError) as error:
        raise CheckpointError(f"checkpoint {path}: not a GNG-DT state ({error})") from error
    check_workspace(path, state, config)
    counters = counters_from_metadata(path, metadata.get("counters", {}))
    counters.last_sequence = -1  # a new capture restarts its sequence numbers
    saved_params = json.loads(str(state["params"]))
    ignored = sorted(name for name, value in config.model.items()
                     if saved_params.get(name) != value)
    if ignored:  # the learned network carries its parameters; changing them mid-life is not
        log.warning("resuming %s with its own parameters; ignoring the requested %s", path,
                    ", ".join(f"{name}={config.model[name]!r}" for name in ignored))
    frame_id = metadata.get("frame_id")
    if frame_id is not None and not isinstance(frame_id, str):
        raise CheckpointError(f"checkpoint {path}: frame_id is {frame_id!r}, not a name")
    log.info("resumed from %s: %d nodes, %d steps, in frame %r", path, model.n_nodes_,
             model.n_steps_, frame_id)
    learner = FrameLearner(camera, config, model=model, counters=counters, frame_id=frame_id)
    tracker = {key[len(TRACKER_PREFIX):]: value for key, value in state.items()
               if key.startswith(TRACKER_PREFIX)}
    if learner.tracking is not None and tracker:
        try:
            learner.tracking.set_state(tracker)
        except (KeyError, ValueError, TypeError) as error:
            raise CheckpointError(f"checkpoint {path}: {error}") from error
    return learner


#: the learner's colours are 8-bit RGB (and averages of them): a node's or a remembered
#: sample's colour outside this range is a forged or broken file
COLOR_RANGE = (0.0, 255.0)


def check_workspace(path: Path, state: dict, config: LearnerConfig) -> None:
    """Every array of a checkpoint a learner would use must hold what the learner could have
    made (`GNGDT.from_state` and the tracker check finiteness and consistency): positions (the
    nodes, the rehearsal memory, the camera's pose, the tracker's pose and plane memory) within
    the workspace its poses may span (`PoseLimits`), colours (the nodes', the memory's) within
    8-bit RGB. Anything beyond is a forged or broken file, and would be learned from (colours
    at 1e300 were, with overflow warnings)."""
    limits = config.options.pose_limits()
    centre, scale = None, 1.0
    if limits.workspace_around == "first-camera" and "camera_pose" in state:
        # the first camera is unknown here; every camera lies within a box of twice the
        # workspace of the last one, and the surfaces it saw a little beyond
        centre, scale = np.asarray(state["camera_pose"], dtype=np.float64)[:3, 3], 3.0
    positions = {POS: "nodes", "memory_positions": "remembered samples",
                 "camera_pose": "camera poses", f"{TRACKER_PREFIX}pose": "tracked poses",
                 f"{TRACKER_PREFIX}plane_points": "tracked plane points"}
    for key, what in positions.items():
        if key not in state:
            continue
        try:
            beyond = points_beyond_workspace(_positions_of(key, state[key]), limits, centre,
                                             scale)
        except (ValueError, TypeError) as error:
            raise CheckpointError(f"checkpoint {path}: {key}: {error}") from error
        if beyond:
            raise CheckpointError(
                f"checkpoint {path}: {beyond} {what} lie beyond the workspace of "
                f"{limits.workspace_m:g} m (pose_workspace_m); not a map this learner made")
    for key, what in ((COL, "node colours"), ("memory_colors", "remembered colours")):
        colors = np.asarray(state.get(key, np.zeros((0, 3))), dtype=np.float64)
        outside = ~((colors >= COLOR_RANGE[0]) & (colors <= COLOR_RANGE[1]))
        if outside.any():
            raise CheckpointError(
                f"checkpoint {path}: {int(outside.any(axis=-1).sum())} {what} lie outside "
                f"8-bit RGB (0-255; e.g. {colors[outside][0]:g}); not a map this learner made")


def _positions_of(key: str, array: np.ndarray) -> np.ndarray:
    """The (N, 3) positions an array of a checkpoint holds (a pose: its translation; a tracker
    without a pose yet holds NaN)."""
    array = np.asarray(array, dtype=np.float64)
    if key.endswith("pose"):
        if array.shape != (4, 4):
            raise ValueError(f"shape {array.shape}, not a (4, 4) pose")
        return np.zeros((0, 3)) if np.isnan(array).all() else array[:3, 3]
    if array.size % 3:
        raise ValueError(f"shape {array.shape}, not positions")
    return array


def counters_from_metadata(path: Path, saved: Any) -> Counters:
    """The counters kept in a checkpoint's metadata, type-checked (``CheckpointError``)."""
    if not isinstance(saved, dict):
        raise CheckpointError(f"checkpoint {path}: counters are not a mapping")
    values: dict[str, Any] = {}
    for item in fields(Counters):
        if item.name not in saved:
            continue
        value = saved[item.name]
        expected = float if item.type in ("float", float) else int
        if isinstance(value, bool) or not isinstance(value, int | float) or (
                expected is int and not isinstance(value, int)):
            raise CheckpointError(
                f"checkpoint {path}: counter {item.name} is {value!r}, expected a number")
        low = -1 if item.name == "last_sequence" else 0
        if not (low <= value <= MAX_LOADED_COUNTER and math.isfinite(value)):
            raise CheckpointError(
                f"checkpoint {path}: counter {item.name} is {value!r}, outside {low}..2**62")
        values[item.name] = expected(value)
    return Counters(**values)


def clean_checkpoint_directory(path: Path) -> None:
    """Remove the temporaries a killed learner left beside ``path`` (under its lock)."""
    removed = remove_stale_temporaries(path)
    if removed:
        log.warning("removed %d stale checkpoint temporaries left by an interrupted write: %s",
                    len(removed), ", ".join(item.name for item in removed))
