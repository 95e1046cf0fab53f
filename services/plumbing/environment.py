"""The environment variables gngdt reads, parsed once at the command-line edge and passed down.

`gngdt.services.cli.main` calls `read_environment` before anything else and hands the result to
the subcommand as ``args.environment``; nothing below reads ``os.environ``. Every value is
range-checked here: a wrong one (``GNGDT_SHM_POOL_MB=inf``, ``GNGDT_PARENT_PID=abc``) is
ignored with a warning naming it (`Environment.problems`, logged once logging is set up), never
a crash deep in a service.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = [
    "MAX_SHM_POOL_MB",
    "PARENT_ENV",
    "RERUN_CLI_ENV",
    "ROS_DOMAIN_ENV",
    "SHARED_MEMORY_POOL_ENV",
    "Environment",
    "read_environment",
]

#: each publisher's shared-memory pool in MiB instead of one sized from its payloads (0: no
#: gngdt pool, zenoh's own transport optimisation only)
SHARED_MEMORY_POOL_ENV = "GNGDT_SHM_POOL_MB"
#: the largest pool accepted, MiB: eight of the largest message zenoh carries (32 MiB) fit
MAX_SHM_POOL_MB = 1024.0
#: set by a gngdt process for its gngdt children: the parent's pid, which they die with
PARENT_ENV = "GNGDT_PARENT_PID"
#: ROS 2's domain id (`gngdt ros2` judges its range: an error there names it)
ROS_DOMAIN_ENV = "ROS_DOMAIN_ID"
#: rerun's own variable: the rerun binary to run instead of the one rerun-sdk ships
RERUN_CLI_ENV = "RERUN_CLI_PATH"


@dataclass(frozen=True)
class Environment:
    """What gngdt takes from its environment (the defaults: an empty one)."""

    #: GNGDT_SHM_POOL_MB in bytes (0: no pool); None: each pool sized from its first payload
    shm_pool_bytes: int | None = None
    #: GNGDT_PARENT_PID: the pid of the gngdt process this one dies with
    parent_pid: int | None = None
    #: ROS_DOMAIN_ID as given, stripped ("" when unset)
    ros_domain_id: str = ""
    #: RERUN_CLI_PATH, when set
    rerun_cli_path: str | None = None
    #: one sentence per value ignored, naming the variable and what it must be
    problems: tuple[str, ...] = ()


def _pool_bytes(text: str) -> tuple[int | None, str]:
    """(bytes or None, problem) of a GNGDT_SHM_POOL_MB value."""
    try:
        megabytes = float(text)
    except ValueError:
        megabytes = math.nan
    if not 0.0 <= megabytes <= MAX_SHM_POOL_MB:  # also NaN and inf
        return None, (f"{SHARED_MEMORY_POOL_ENV}={text!r} is not a number of MiB from 0 to "
                      f"{MAX_SHM_POOL_MB:g}; pools are sized from their payloads")
    return int(megabytes * 1024 * 1024), ""


def _parent_pid(text: str) -> tuple[int | None, str]:
    """(pid or None, problem) of a GNGDT_PARENT_PID value."""
    if text.isdigit() and 1 < int(text) < 2**22 + 1:  # Linux's largest pid_max is 2**22
        return int(text), ""
    return None, f"{PARENT_ENV}={text!r} is not a process id; ignored"


def read_environment(environ: Mapping[str, str] | None = None) -> Environment:
    """The `Environment` of ``environ`` (default ``os.environ``), every value range-checked."""
    environ = os.environ if environ is None else environ
    problems = []
    values: dict[str, object] = {}
    for name, field, parse in ((SHARED_MEMORY_POOL_ENV, "shm_pool_bytes", _pool_bytes),
                               (PARENT_ENV, "parent_pid", _parent_pid)):
        text = environ.get(name, "").strip()
        if text:
            values[field], problem = parse(text)
            if problem:
                problems.append(problem)
    return Environment(**values, ros_domain_id=environ.get(ROS_DOMAIN_ENV, "").strip(),
                       rerun_cli_path=environ.get(RERUN_CLI_ENV) or None,
                       problems=tuple(problems))
