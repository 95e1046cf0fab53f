"""GNG-DT (growing neural gas with different topologies) and the paper's baselines.

Pure computation: numpy, numba and scipy only; no I/O, no transport. The names below load on
first use, so that importing one light module of the package (``gngdt_core.geometry``) does not
pay for numba and scipy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gngdt_core.baselines import GNG, GNGW
    from gngdt_core.clustering import cluster_count, connected_component_labels
    from gngdt_core.metrics import adjusted_rand_index, cluster_centre_errors, quantization_error
    from gngdt_core.model import GNGDT
    from gngdt_core.synthetic import DATA1_CENTRES, make_data1, make_data2

#: public name -> the module defining it
_EXPORTS = {
    "GNG": "baselines", "GNGW": "baselines", "GNGDT": "model",
    "cluster_count": "clustering", "connected_component_labels": "clustering",
    "adjusted_rand_index": "metrics", "cluster_centre_errors": "metrics",
    "quantization_error": "metrics",
    "DATA1_CENTRES": "synthetic", "make_data1": "synthetic", "make_data2": "synthetic",
}

__all__ = [
    "DATA1_CENTRES",
    "GNG",
    "GNGDT",
    "GNGW",
    "adjusted_rand_index",
    "cluster_centre_errors",
    "cluster_count",
    "connected_component_labels",
    "make_data1",
    "make_data2",
    "quantization_error",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'gngdt_core' has no attribute {name!r}")
    return getattr(importlib.import_module(f"gngdt_core.{module}"), name)
