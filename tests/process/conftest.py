"""Fixtures of the tests that start real processes."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels() -> None:
    """Compile the learner's numba kernels once, in this process, before any service starts: a
    service then loads them from numba's disk cache in about a second, so a test waiting for a
    service measures the service, not a first compile (a minute or more on a busy machine).
    How `gngdt run` copes with a cold start is tested in test_run_startup.py."""
    from gngdt.core.learner.warm_up import warm_up_learner
    from gngdt.io.profiles import load_profile

    warm_up_learner(load_profile(None).config)
