"""GNG-DT (growing neural gas with different topologies) and the paper's baselines.

Pure computation: numpy, numba and scipy only; no I/O, no transport.
"""

from gngdt_core.baselines import GNG, GNGW
from gngdt_core.clustering import cluster_count, connected_component_labels
from gngdt_core.metrics import adjusted_rand_index, cluster_centre_errors, quantization_error
from gngdt_core.model import GNGDT
from gngdt_core.synthetic import DATA1_CENTRES, make_data1, make_data2

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
