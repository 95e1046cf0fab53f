"""Deprecated: `services.recording.reader` moved to `gngdt_io.mcap_reader`
(gngdt 0.2); this path goes in the next release."""

from gngdt_core._compat import forward_to

__getattr__ = forward_to("services.recording.reader", "gngdt_io.mcap_reader")
