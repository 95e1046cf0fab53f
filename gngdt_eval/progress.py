"""A one-line progress counter on stderr (no dependency; quiet when stderr is not a terminal)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """``[#####-----]  12/50  24%  eta 0:01:10  label`` rewritten in place on ``stream``.

    When ``stream`` is not a terminal, a plain line is written every ``1/10`` of the total, so logs
    from CI stay short but still show that work is moving.
    """

    def __init__(self, total: int, label: str = "", stream: TextIO | None = None, width: int = 30):
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.done = 0
        self._start = time.monotonic()
        self._interactive = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_decile = -1

    def advance(self, count: int = 1) -> None:
        """Mark ``count`` more units of work as done and redraw."""
        self.done = min(self.done + count, self.total)
        self._draw()

    def close(self) -> None:
        """Finish the line (prints the elapsed time)."""
        elapsed = time.monotonic() - self._start
        line = self._line() if self._interactive else f"{self.done}/{self.total} {self.label}"
        self.stream.write(f"{line}  done in {_clock(elapsed)}\n")
        self.stream.flush()

    def _line(self) -> str:
        fraction = self.done / self.total
        filled = round(fraction * self.width)
        elapsed = time.monotonic() - self._start
        eta = elapsed / fraction - elapsed if fraction > 0 else float("nan")
        bar = "#" * filled + "-" * (self.width - filled)
        eta_text = _clock(eta) if eta == eta else "?"
        return (
            f"[{bar}] {self.done:>{len(str(self.total))}}/{self.total} {fraction:4.0%} "
            f"eta {eta_text} {self.label}"
        )

    def _draw(self) -> None:
        if self._interactive:
            self.stream.write("\r" + self._line())
            if self.done == self.total:
                self.stream.write("\n")
        else:
            decile = int(10 * self.done / self.total)
            if decile == self._last_decile:
                return
            self._last_decile = decile
            self.stream.write(self._line() + "\n")
        self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = max(0, round(seconds))
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"
