"""Issue 38's attacks through files and settings, for ``bench_hostile.py`` (`hostile_doors`
has those through live clients): a recording calibrated with fx = 1e-30, a camera.json whose
principal point is 1e30 px off, a transform stamped 2038, a 100 m jump 25 s after the last
frame, noise frames with ``--track``, a checkpoint with colours at 1e300, ``GNGDT_SHM_POOL_MB
=inf``, a run killed with SIGKILL. Each is a real `gngdt` command on small generated input; one
row each: exit codes, peak RSS, whether a traceback reached the user, what came of it."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from hostile_trust import (
    GNGDT,
    PEAK_RSS,
    Attack,
    attack,
    crafted_checkpoint,
    descendants,
    finish,
    image_folder,
    line_with,
    recording,
    run,
    run_credentials,
    run_summary,
    start,
    walk_frames,
)

SECOND = 1_000_000_000


def calibration_attacks(folder: Path) -> list[Attack]:
    """A recording whose every calibration has fx = 1e-30; a folder whose camera.json puts cx
    at -1e30; the same as --camera-json of a good recording."""
    from gngdt.io.frame import CameraIntrinsics

    frames = walk_frames(8)
    k = frames[0].intrinsics
    tiny = CameraIntrinsics(k.width, k.height, 1e-30, k.fy, k.cx, k.cy)
    absurd = recording(folder / "fx_1e-30.mcap", [replace(frame, intrinsics=tiny)
                                                  for frame in frames])
    images = image_folder(folder / "cx_off", frames)
    camera = json.loads((images / "camera.json").read_text())
    (images / "camera.json").write_text(json.dumps({**camera, "cx": -1e30}))
    good = recording(folder / "good.mcap", frames)
    rows = []
    for label, command in (
            ("recording calibrated with fx = 1e-30", [str(absurd)]),
            ("camera.json with cx = -1e30", [str(images)]),
            ("--camera-json with cx = -1e30", [str(good), "--camera-json",
                                               str(images / "camera.json")])):
        ran = run([*GNGDT, "run", *command, "--fast", "--save", str(folder / f"{len(rows)}.rrd")],
                  folder / f"run-{len(rows)}.log")
        rows.append(attack(label, {"run": ran}, line_with(ran.output, "refused",
                                                          "invalid")[:90]))
    return rows


def pose_attacks(folder: Path) -> list[Attack]:
    """A walk with one transform ``map -> decoy`` and one on the camera's link stamped 2038;
    a walk whose frame 6 jumps 100 m, stamped 25 s after frame 5."""
    from gngdt.io.mcap.writer import RecordingWriter

    frames = walk_frames(12)
    decoy = folder / "tf_2038.mcap"
    with RecordingWriter(decoy) as writer:
        for index, frame in enumerate(frames):
            if index == 3:
                far, forged = 2_147_483_000 * SECOND, np.eye(4)
                forged[:3, 3] = 50.0
                writer.write_transform(np.eye(4), "map", "decoy", far)
                writer.write_transform(forged, frame.pose.frame_id, writer.frame_id, far)
            writer.write_frame(frame)

    def jump(index: int, pose: np.ndarray) -> np.ndarray:
        if index != 6:
            return pose
        moved = pose.copy()
        moved[0, 3] += 100.0
        return moved

    jumped = [replace(frame, timestamp_ns=frame.timestamp_ns + (25 * SECOND if index >= 6
                                                                else 0))
              for index, frame in enumerate(frames)]
    rows = []
    for label, path in (("/tf stamped 2038 (decoy and camera link)", decoy),
                        ("100 m jump 25 s after the last frame",
                         recording(folder / "jump.mcap", jumped, jump))):
        ran = run([*GNGDT, "run", str(path), "--rate", "0.5", "--save",
                   str(folder / f"{len(rows)}.rrd")], folder / f"run-{len(rows)}.log")
        rows.append(attack(label, {"run": ran}, run_summary(ran)[:90]))
    return rows


def noise_attack(folder: Path) -> list[Attack]:
    """30 frames of random depth with --track: no map is started from them."""
    frames = walk_frames(30)
    rng = np.random.default_rng(0)
    noise = [replace(frame, pose=None, depth=rng.integers(500, 5000, frame.depth.shape
                                                          ).astype(np.uint16))
             for frame in frames]
    path = recording(folder / "noise.mcap", noise)
    ran = run([*GNGDT, "run", str(path), "--track", "--fast", "--save",
               str(folder / "noise.rrd")], folder / "run-noise.log")
    return [attack("noise frames with --track", {"run": ran},
                   (line_with(ran.output, "nodes:") + " / "
                    + line_with(ran.output, "smooth"))[:90])]


def checkpoint_attack(folder: Path) -> list[Attack]:
    def colours(array):
        array[0] = 1e300
        return array

    path = crafted_checkpoint(folder / "colours.npz", memory_colors=colours)
    ran = run([*GNGDT, "learn", "--checkpoint", str(path), "--router-wait", "0"],
              folder / "learn.log", 120)
    return [attack("checkpoint: memory_colors at 1e300", {"learn": ran},
                   line_with(ran.output, "ERROR")[:90])]


def environment_attacks(folder: Path) -> list[Attack]:
    """`gngdt run` with GNGDT_SHM_POOL_MB=inf and =1e308 (each service read it)."""
    frames = recording(folder / "walk.mcap", walk_frames(4))
    rows = []
    for value in ("inf", "1e308"):
        log = folder / f"run-{value}.log"
        with open(log, "wb") as output:
            process = subprocess.Popen(
                [sys.executable, "-c", PEAK_RSS, *GNGDT, "run", str(frames), "--fast", "--save",
                 str(folder / f"{value}.rrd")], stdout=output, stderr=subprocess.STDOUT,
                start_new_session=True, env={**os.environ, "GNGDT_SHM_POOL_MB": value})
        ran = finish(process, log)
        rows.append(attack(f"GNGDT_SHM_POOL_MB={value}", {"run": ran},
                           line_with(ran.output, "GNGDT_SHM_POOL_MB")[:90]))
    return rows


def credentials_attack(folder: Path, recording_path: Path | None = None) -> list[Attack]:
    """`gngdt run` killed with SIGKILL, then another run: the first one's passwords are gone."""
    path = recording_path or recording(folder / "walk.mcap", walk_frames(8))
    killed = start([*GNGDT, "run", str(path), "--rate", "0.1", "--save",
                    str(folder / "killed.rrd")], folder / "run-killed.log")
    credentials = run_credentials(killed.pid)
    for pid in [killed.pid, *descendants(killed.pid)]:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    finish(killed, folder / "run-killed.log", 30)
    left = (credentials / "router-users.txt").exists()
    ran = run([*GNGDT, "run", str(path), "--fast", "--save", str(folder / "next.rrd")],
              folder / "run-next.log")
    gone = not (credentials / "router-users.txt").exists()
    return [attack("run killed with SIGKILL, then another run", {"next run": ran},
                   f"passwords left by the kill: {left}; after the next run: "
                   f"{'removed' if gone else 'STILL THERE'}")]


def input_attacks(folder: Path) -> list[Attack]:
    """Every attack of this module, each in a folder of its own."""
    rows = []
    for part in (calibration_attacks, pose_attacks, noise_attack, checkpoint_attack,
                 environment_attacks, credentials_attack):
        part_folder = folder / part.__name__
        part_folder.mkdir()
        rows += part(part_folder)
    return rows
