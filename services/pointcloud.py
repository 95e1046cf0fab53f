"""Deprecated: `services.pointcloud` moved to `gngdt_io.deproject`
(gngdt 0.2); this path goes in the next release."""

from gngdt_core._compat import forward_to

__getattr__ = forward_to("services.pointcloud", "gngdt_io.deproject")
