"""CI runs exactly what developers run: one Hypothesis profile, whatever ``CI`` says."""

from __future__ import annotations


def test_the_profile_is_derandomised_and_keeps_no_database() -> None:
    from hypothesis import settings

    assert settings.default.derandomize is True
    assert settings.default.database is None


