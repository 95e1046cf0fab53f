"""Deprecated: the packing helpers live by message family (gngdt 0.2): `schemas.messages`
(parsing, timestamps, PackedArray), `schemas.images` (raw images, calibration), `schemas.clouds`
(point clouds, cloud poses, transforms), `schemas.topology` and `schemas.status`. This path
forwards there until the next release."""

from gngdt_core._compat import forward_to

_FAMILIES = ("schemas.clouds", "schemas.images", "schemas.messages", "schemas.status",
             "schemas.topology")


def __getattr__(name: str):
    import importlib

    for family in _FAMILIES:
        if hasattr(importlib.import_module(family), name):
            return forward_to("schemas.packing", family)(name)
    raise AttributeError(f"module 'schemas.packing' has no attribute {name!r}")
