"""Old import paths kept for one release: a module that only forwards to the new one, warning."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any


def forward_to(old: str, new: str) -> Callable[[str], Any]:
    """A module ``__getattr__`` for the old path ``old``: every name comes from ``new``, with a
    DeprecationWarning naming where to import it from."""

    def __getattr__(name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        warnings.warn(f"{old} moved to {new}; import {name} from there ({old} goes in the next "
                      "release)", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(new), name)

    return __getattr__
