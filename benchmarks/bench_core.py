"""Learning speed of GNG-DT (3-D position + colour + normal) once the node count has saturated.

Prints steps/s of the numba kernel at 100, 1,000 and 10,000 nodes, of the readable NumPy
per-step reference on the same saturated networks (fewer steps), their ratio, and the numba
first-call compile time (cold cache, in a subprocess) and cached load time.

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

from gngdt_core import GNGDT, make_data2
from gngdt_core.reference import ReferenceGNGDT

_FIRST_CALL = """
import time
t0 = time.perf_counter()
from gngdt_core import GNGDT, make_data2
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


if __name__ == "__main__":
    main()
