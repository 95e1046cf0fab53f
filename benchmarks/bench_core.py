"""Learning speed of GNG-DT (3-D position + colour + normal) once the node count has saturated.

Prints steps/s of the numba kernel at 100, 1,000 and 10,000 nodes, of the readable NumPy
per-step reference on the same saturated networks (fewer steps), their ratio, and the numba
first-call compile time (cold cache, in a subprocess) and cached load time.

Then forgetting (``utility_k``) and the learner's whole profile (forgetting and rehearsal,
``replay_share``) at 1,000 nodes against the same network without either, in the same run: on
Data2 seen as a depth camera's batch (one long call), and as the learner runs it, 10,000 steps a
frame with the frame's camera pose, on virtual Kinect frames of the walking camera
(``tabletop_walk``, 320x240); the per-frame time includes judging which nodes the sensor could
see and, with rehearsal, keeping the memory (carving, drawing, offering).

    python benchmarks/bench_core.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from gngdt.core import GNGDT
from gngdt.eval.reference import ReferenceGNGDT
from gngdt.eval.synthetic import make_data2

_FIRST_CALL = """
import time
t0 = time.perf_counter()
from gngdt.core import GNGDT
from gngdt.eval.synthetic import make_data2
positions, colors, _ = make_data2(n_points=2000, random_state=0)
t1 = time.perf_counter()
GNGDT(max_nodes=100, random_state=0).fit(positions, colors, n_steps=1000)
print(time.perf_counter() - t1, t1 - t0)
"""


def first_call_seconds(cache_dir: str) -> float:
    """Seconds of the first fit in a fresh process using ``cache_dir`` as numba's cache."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run([sys.executable, "-c", _FIRST_CALL], env=env, check=True,
                         capture_output=True, text=True).stdout.split()
    return float(out[0])


def saturated_model(positions: np.ndarray, colors: np.ndarray, n_nodes: int) -> GNGDT:
    model = GNGDT(max_nodes=n_nodes, random_state=0)
    # lambda_ = 500: growth needs about 500 * n_nodes steps; then some settling
    model.fit(positions, colors, n_steps=500 * n_nodes + 200_000)
    assert model.n_nodes_ == n_nodes, model.n_nodes_
    return model


def steps_per_second(learner: GNGDT | ReferenceGNGDT, positions: np.ndarray,
                     colors: np.ndarray, n_steps: int) -> float:
    start = time.perf_counter()
    learner.partial_fit(positions, colors, n_steps=n_steps)
    return n_steps / (time.perf_counter() - start)


def forgetting_speed(positions: np.ndarray, colors: np.ndarray, fast_steps: int,
                     frames: int) -> None:
    """Steps/s at 1,000 nodes without forgetting, with it, and with the learner's whole profile
    (forgetting and rehearsal), on one batch and frame by frame."""
    from gngdt.core.learner.frame_learner import LEARNER_MODEL_DEFAULTS
    from gngdt.io.deproject import Deprojector
    from gngdt.io.synth.render import render_scene

    profiles = {"off": {}, "forgetting": {"utility_k": LEARNER_MODEL_DEFAULTS["utility_k"]},
                "profile": LEARNER_MODEL_DEFAULTS}
    # Data2 as a depth camera's batch: in front of the camera, z from 200 to 300 units
    camera_batch = positions + np.array([-150.0, -150.0, 200.0])
    print(f"forgetting at 1,000 nodes, and the learner's profile ({LEARNER_MODEL_DEFAULTS}), "
          "against the same network without either:")
    print(f"{'workload':>34} {'off steps/s':>13} {'forgetting':>13} {'profile':>13} "
          f"{'forg./off':>9} {'prof./off':>9}")

    def report(workload: str, rates: dict[str, float]) -> None:
        print(f"{workload:>34} {rates['off']:>13,.0f} {rates['forgetting']:>13,.0f} "
              f"{rates['profile']:>13,.0f} {rates['forgetting'] / rates['off']:>9.2f} "
              f"{rates['profile'] / rates['off']:>9.2f}")

    rates = {}
    for name, extra in profiles.items():
        model = GNGDT(max_nodes=1_000, random_state=0, **extra)
        model.fit(camera_batch, colors, n_steps=700_000)
        rates[name] = steps_per_second(model, camera_batch, colors, fast_steps)
    report("Data2 batch, one call", rates)

    deproject = Deprojector()
    views = []
    for frame in render_scene("tabletop_walk", frames, width=320, height=240):
        points, point_colors = deproject(frame.depth, frame.color, frame.intrinsics)
        views.append((points, point_colors, frame.pose.matrix))
    for name, extra in profiles.items():
        model = GNGDT(max_nodes=1_000, random_state=0, **extra)
        for points, point_colors, pose in views[: frames // 2] * 3:  # fill up to 1,000 nodes
            model.partial_fit(points, point_colors, n_steps=10_000, camera_pose=pose)
        assert model.n_nodes_ == 1_000, model.n_nodes_
        start = time.perf_counter()
        for points, point_colors, pose in views[frames // 2:]:
            model.partial_fit(points, point_colors, n_steps=10_000, camera_pose=pose)
        rates[name] = 10_000 * (frames - frames // 2) / (time.perf_counter() - start)
    report("walk frames, 10,000 steps + pose", rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps (smoke run)")
    args = parser.parse_args()
    fast_steps = 300_000 if args.quick else 3_000_000
    naive_steps = 300 if args.quick else 2_000

    with tempfile.TemporaryDirectory() as cold_cache:
        cold = first_call_seconds(cold_cache)
        warm = first_call_seconds(cold_cache)
    print(f"numba first call: {cold:.1f} s compiling (cold cache), {warm:.2f} s with the cache")

    positions, colors, _ = make_data2(random_state=0)
    print(f"data: Data2, {len(positions)} points, 3-D position + colour (+ normal topology)")
    print(f"{'nodes':>7} {'numba steps/s':>15} {'numpy steps/s':>15} {'ratio':>8}")
    for n_nodes in (100, 1_000, 10_000):
        model = saturated_model(positions, colors, n_nodes)
        reference = ReferenceGNGDT.from_model(model)
        fast = steps_per_second(model, positions, colors, fast_steps)
        naive = steps_per_second(reference, positions, colors, naive_steps)
        print(f"{n_nodes:>7} {fast:>15,.0f} {naive:>15,.0f} {fast / naive:>8,.0f}")
    forgetting_speed(positions, colors, fast_steps, 20 if args.quick else 60)


if __name__ == "__main__":
    main()
