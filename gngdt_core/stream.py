"""Deprecated: `gngdt_core.stream` moved to `gngdt_core.schedule`
(gngdt 0.2); this path goes in the next release."""

from gngdt_core._compat import forward_to

__getattr__ = forward_to("gngdt_core.stream", "gngdt_core.schedule")
