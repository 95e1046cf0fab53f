"""GNG-DT (growing neural gas with different topologies) and the paper's baselines.

Pure computation: numpy, numba and scipy only; no I/O, no transport. By concern:

- `gas`: the estimators (`GNGDT`, the paper's `GNG` and `GNGW`), their state, sampling, queries,
  rehearsal and node budget
- `segmentation`: segments a robot can use, from a learned network
- `odometry`: camera tracking against the learned map, and checks of camera poses
- `objects`: objects from clusters or segments, with ids that persist from frame to frame
- `learner`: the per-frame policies that turn a stream of frames into a network
- `sensor`: the camera as the algorithm sees it (intrinsics, rigid transforms, depth, views)
- `kernels`: the numba kernels, pure functions over arrays, one module per data structure
- `parameters` (every parameter declared once), `clustering` (connected components and the
  registry of clusterings), `metrics` (evaluation measures)

The names below load on first use, so that importing one light module of the package
(``gngdt.core.sensor.geometry``) does not pay for numba and scipy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gngdt.core.clustering import cluster_count, connected_component_labels
    from gngdt.core.gas.baselines import GNG, GNGW
    from gngdt.core.gas.model import GNGDT
    from gngdt.core.metrics import adjusted_rand_index, cluster_centre_errors, quantization_error

#: public name -> the module defining it
_EXPORTS = {
    "GNG": "gas.baselines", "GNGW": "gas.baselines", "GNGDT": "gas.model",
    "cluster_count": "clustering", "connected_component_labels": "clustering",
    "adjusted_rand_index": "metrics", "cluster_centre_errors": "metrics",
    "quantization_error": "metrics",
}

__all__ = [
    "GNG",
    "GNGDT",
    "GNGW",
    "adjusted_rand_index",
    "cluster_centre_errors",
    "cluster_count",
    "connected_component_labels",
    "quantization_error",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'gngdt.core' has no attribute {name!r}")
    return getattr(importlib.import_module(f"gngdt.core.{module}"), name)
