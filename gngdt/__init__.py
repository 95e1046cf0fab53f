"""gngdt: online, unsupervised 3D perception with GNG-DT.

One import namespace for every part; each part lives in its own top-level folder of the
repository (a package-dir mapping in pyproject.toml):

- `gngdt.core` (gngdt_core/): the algorithm, numpy/numba/scipy only, no I/O
- `gngdt.schemas` (schemas/): the wire contracts, protobuf messages and their numpy packing
- `gngdt.io` (gngdt_io/): recordings, cameras, ROS 2, outputs
- `gngdt.eval` (gngdt_eval/): the evaluations
- `gngdt.services` (services/): the processes and the `gngdt` command line
- `gngdt.config` (config/): example configuration files
"""

from __future__ import annotations


def __getattr__(name: str) -> str:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("gngdt")
        except PackageNotFoundError:  # a checkout that was never installed
            return "unknown (not installed)"
    raise AttributeError(f"module 'gngdt' has no attribute {name!r}")
