"""Deprecated: `services.recording.frame` moved to `gngdt_io.frame`
(gngdt 0.2); this path goes in the next release."""

from gngdt_core._compat import forward_to

__getattr__ = forward_to("services.recording.frame", "gngdt_io.frame")
