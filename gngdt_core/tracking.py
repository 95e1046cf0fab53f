"""Deprecated: `gngdt_core.tracking` moved to `gngdt_core.cluster_tracking`
(gngdt 0.2); this path goes in the next release."""

from gngdt_core._compat import forward_to

__getattr__ = forward_to("gngdt_core.tracking", "gngdt_core.cluster_tracking")
