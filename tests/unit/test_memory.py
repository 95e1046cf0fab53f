"""Giving memory back (`gngdt.io.memory`), measured in a fresh interpreter's resident size."""

from __future__ import annotations

import subprocess
import sys

import pytest

#: frees a 24 MB buffer (glibc then keeps buffers of up to 24 MB in its arenas), then fills and
#: frees a 16 MB one: how much of it stays resident, MB
PROGRAM = """
import sys
import numpy as np
from gngdt.io.memory import map_large_buffers

def resident_mb():
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024

if sys.argv[1] == "mapped":
    assert map_large_buffers()
np.ones(24 << 20, np.uint8)
before = resident_mb()
np.ones(16 << 20, np.uint8)
print(resident_mb() - before)
"""


def kept_mb(mode: str) -> float:
    done = subprocess.run([sys.executable, "-c", PROGRAM, mode], capture_output=True, text=True,
                          timeout=60, check=True)
    return float(done.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_large_buffers_freed_leave_at_once() -> None:
    from gngdt.io.memory import _libc

    if _libc is None:
        pytest.skip("not glibc")
    assert kept_mb("mapped") < 4
