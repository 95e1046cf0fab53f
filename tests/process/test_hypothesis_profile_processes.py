"""CI runs exactly what developers run: one Hypothesis profile, whatever ``CI`` says."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]  # tests/, where conftest.py is

PROBE = """
import sys
sys.path.insert(0, {tests!r})
import conftest  # registers and loads the project's profile, as pytest does first
from hypothesis import settings
print(repr(settings.default))
"""


def _default_settings(ci: str | None) -> str:
    env = {key: value for key, value in os.environ.items()
           if key not in ("CI", "GITHUB_ACTIONS", "TF_BUILD", "BUILDKITE", "CIRCLECI",
                          "CODEBUILD_BUILD_ID", "GITLAB_CI", "JENKINS_URL", "TEAMCITY_VERSION")}
    if ci is not None:
        env["CI"] = ci
    completed = subprocess.run([sys.executable, "-c", PROBE.format(tests=str(TESTS))],
                               capture_output=True, text=True, env=env, timeout=120, check=True)
    return completed.stdout.strip()


def test_ci_and_a_developer_machine_run_the_same_hypothesis_settings() -> None:
    local, ci = _default_settings(None), _default_settings("true")
    assert local == ci
    assert "derandomize=True" in local and "database=None" in local
