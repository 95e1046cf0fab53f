"""Giving freed memory back to the system (Linux, glibc).

After a burst of large buffers (a Foxglove client's backlog, a flood of ROS 2 images), glibc
keeps the freed memory in its arenas: a process that peaked at gigabytes stays there long after
(measured: 2.5 GB of a logger's 2.7 GB peak 20 s after 40 Foxglove clients left; 907 MB of the
ROS 2 bridge's 1.25 GB after an image flood). ``malloc_trim(0)`` returns the free pages of every
arena. Elsewhere (another libc, another system) it does nothing.

Better still, a process that handles one large buffer after another (images) has them mapped
each on its own (`map_large_buffers`): freed, they are gone from its memory at once.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import sys
import time

__all__ = ["LARGE_BUFFER_BYTES", "TrimPacer", "map_large_buffers", "release_free_memory",
           "resident_bytes"]

log = logging.getLogger(__name__)

_libc = None
if sys.platform.startswith("linux"):
    try:
        _libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        _libc.malloc_trim.argtypes = [ctypes.c_size_t]
        _libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    except (OSError, AttributeError):  # not glibc (musl has no malloc_trim)
        _libc = None


_PAGE_BYTES = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def resident_bytes() -> int | None:
    """This process's resident memory now (bytes, from ``/proc/self/statm``: a few
    microseconds); None where there is no ``/proc``."""
    try:
        with open("/proc/self/statm", "rb") as statm:
            return int(statm.read().split()[1]) * _PAGE_BYTES
    except (OSError, IndexError, ValueError):
        return None


#: glibc's mallopt parameter M_MMAP_THRESHOLD (malloc.h)
_M_MMAP_THRESHOLD = -3
#: `map_large_buffers`' default: a 4K depth image (16.6 MB) and larger. Mapping smaller ones too
#: (1 MB) took another 7-10 ms of the bridge's CPU a frame at 30 fps with 4.6 MB VGA clouds (fresh
#: pages faulted in each time) for 50 MB less peak under a 4K flood
LARGE_BUFFER_BYTES = 16 << 20


def map_large_buffers(threshold_bytes: int = LARGE_BUFFER_BYTES) -> bool:
    """Have malloc map every buffer of ``threshold_bytes`` or more on its own pages, returned to
    the system when it is freed; True when set. glibc does so from 128 kB on, but raises that
    threshold (up to 32 MB) each time such a buffer is freed: from then on the images of a
    flood were carved out of its per-thread arenas and their pages kept there (the ROS 2
    bridge's peak under a 4K flood: 866-892 MB, 746-765 MB with the threshold fixed at 16 MB)."""
    if _libc is None:
        return False
    return bool(_libc.mallopt(_M_MMAP_THRESHOLD, threshold_bytes))


def release_free_memory() -> bool:
    """Give the free pages of every malloc arena back to the system; True when some were."""
    if _libc is None:
        return False
    return bool(_libc.malloc_trim(0))


class TrimPacer:
    """Calls `release_free_memory` when asked (`soon`: something large was, or is being, freed),
    at most every ``min_interval_s`` (a trim walks every arena: ~1-10 ms), from `poll`; twice
    for each request, the second ``min_interval_s`` later (what another thread frees a little
    after the request is given back too)."""

    def __init__(self, min_interval_s: float = 1.0) -> None:
        self.min_interval_s = min_interval_s
        self._wanted = 0
        self._last = 0.0

    def soon(self) -> None:
        self._wanted = 2

    def poll(self) -> None:
        now = time.monotonic()
        if self._wanted and now - self._last >= self.min_interval_s:
            self._wanted -= 1
            self._last = now
            release_free_memory()
