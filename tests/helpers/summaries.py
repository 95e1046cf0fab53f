"""What `gngdt run`'s summary says, read back as numbers."""

from __future__ import annotations


def every_frame_sent(summary: str) -> tuple[int, dict[str, int]]:
    """The frames sent and each named term of the summary's 'every frame sent' line
    (``300 = 298 learned + 2 dropped + ...`` -> ``(300, {"learned": 298, "dropped": 2, ...})``)."""
    line = next(line for line in summary.splitlines() if line.startswith("every frame sent:"))
    sent, terms = line.split(":", 1)[1].split("=")
    named = {}
    for term in terms.split(" + "):
        count, name = term.strip().split(" ", 1)
        named[name.split(" (")[0]] = int(count)
    return int(sent), named
