"""Learning speed of GNG-DT (3-D position + colour + normal) once the node count has saturated.

Prints steps/s of the numba kernel at 100, 1,000 and 10,000 nodes (thread CPU time, the median
of ``--repeat`` runs), of the readable NumPy per-step reference on the same saturated networks
(fewer steps), their ratio, and the numba first-call compile time (cold cache, in a subprocess)
and cached load time.

With ``--cpp PATH`` (a build of ``benchmarks/gng_cpp_driver.cpp``: gng_collection's plain C++
GNG, built outside the repository as that file says) the same sizes are timed in C++ on Data2's
positions in the same run, and the ratio printed: with strict IEEE floats and with subnormals
flushed to zero (as a -ffast-math build runs), beside GNG-DT and beside gngdt's own plain GNG on
positions alone (the same task as the C++). gngdt never depends on it.

Then forgetting (``utility_k``) and the learner's whole profile (forgetting and rehearsal,
``replay_share``) at 1,000 nodes against the same network without either, in the same run: on
Data2 seen as a depth camera's batch (one long call), and as the learner runs it, 10,000 steps a
frame with the frame's camera pose, on virtual Kinect frames of the walking camera
(``tabletop_walk``, 320x240); the per-frame time includes judging which nodes the sensor could
see and, with rehearsal, keeping the memory (carving, drawing, offering).

    python benchmarks/bench_core.py [--quick] [--repeat 3] [--cpp PATH]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from gngdt.core import GNG, GNGDT
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


def steps_per_second(learner: GNG | GNGDT | ReferenceGNGDT, positions: np.ndarray,
                     colors: np.ndarray | None, n_steps: int, repeat: int = 1) -> float:
    """Median steps/s (thread CPU time: other work on the machine does not count) of
    ``repeat`` calls of ``n_steps`` steps each, the learner going on from call to call."""
    rates = []
    for _ in range(repeat):
        start = time.thread_time()
        learner.partial_fit(positions, colors, n_steps=n_steps)
        rates.append(n_steps / (time.thread_time() - start))
    return float(np.median(rates))


def cpp_steps_per_second(driver: str, positions: np.ndarray, sizes: dict[int, int],
                         flush_subnormals: bool) -> dict[int, float]:
    """Steps/s of gng_collection's C++ GNG (``driver``, a build of gng_cpp_driver.cpp) on the
    3-D ``positions`` for each node budget in ``sizes`` (nodes -> timed steps)."""
    with tempfile.NamedTemporaryFile(suffix=".f32") as points:
        positions.astype(np.float32).tofile(points.name)
        out = subprocess.run([driver, points.name, str(int(flush_subnormals)),
                              *(f"{nodes}:{steps}" for nodes, steps in sizes.items())],
                             check=True, capture_output=True, text=True).stdout
    rates = [float(line.split(":")[1].split()[0]) for line in out.splitlines()]
    return dict(zip(sizes, rates, strict=True))


def plain_gng_rates(positions: np.ndarray, sizes: tuple[int, ...], fast_steps: int,
                    repeat: int) -> dict[int, float]:
    """Steps/s of gngdt's own plain GNG on positions alone (the C++ GNG's task) at each size."""
    rates = {}
    for n_nodes in sizes:
        model = GNG(max_nodes=n_nodes, random_state=0)
        model.fit(positions, n_steps=500 * n_nodes + 200_000)
        rates[n_nodes] = steps_per_second(model, positions, None, fast_steps, repeat)
    return rates


def cpp_comparison(driver: str, positions: np.ndarray, rates: dict[int, float],
                   fast_steps: int, repeat: int) -> None:
    """gngdt's steps/s (GNG-DT, and its plain GNG on positions alone) beside the C++ GNG's at
    each size, strict IEEE and subnormals flushed."""
    # the C++ search is brute force (O(nodes) a step): fewer steps at the larger sizes
    sizes = {nodes: max(30_000, fast_steps * 100 // nodes) for nodes in rates}
    ieee = cpp_steps_per_second(driver, positions, sizes, flush_subnormals=False)
    ftz = cpp_steps_per_second(driver, positions, sizes, flush_subnormals=True)
    plain = plain_gng_rates(positions, tuple(rates), fast_steps, repeat)
    print("beside gng_collection's plain C++ GNG (one topology, positions only), same run; "
          "GNG-DT also keeps colour, normals (eq. 16 each step) and three topologies:")
    print(f"{'nodes':>7} {'learner':>8} {'gngdt steps/s':>15} {'C++ steps/s':>13} {'ratio':>7} "
          f"{'C++ FTZ steps/s':>16} {'ratio':>7}")
    for nodes in rates:
        for learner, rate in (("GNG-DT", rates[nodes]), ("GNG", plain[nodes])):
            print(f"{nodes:>7} {learner:>8} {rate:>15,.0f} {ieee[nodes]:>13,.0f} "
                  f"{rate / ieee[nodes]:>7.2f} {ftz[nodes]:>16,.0f} {rate / ftz[nodes]:>7.2f}")


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
    parser.add_argument("--repeat", type=int, default=3,
                        help="timed runs per size; the median is printed")
    parser.add_argument("--cpp", metavar="PATH",
                        help="a build of benchmarks/gng_cpp_driver.cpp: time gng_collection's "
                             "C++ GNG beside gngdt")
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
    rates = {}
    for n_nodes in (100, 1_000, 10_000):
        model = saturated_model(positions, colors, n_nodes)
        reference = ReferenceGNGDT.from_model(model)
        rates[n_nodes] = steps_per_second(model, positions, colors, fast_steps, args.repeat)
        naive = steps_per_second(reference, positions, colors, naive_steps)
        print(f"{n_nodes:>7} {rates[n_nodes]:>15,.0f} {naive:>15,.0f} "
              f"{rates[n_nodes] / naive:>8,.0f}")
    if args.cpp:
        cpp_comparison(args.cpp, positions, rates, fast_steps, args.repeat)
    forgetting_speed(positions, colors, fast_steps, 20 if args.quick else 60)


if __name__ == "__main__":
    main()
