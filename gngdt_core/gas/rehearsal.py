"""A bounded memory of the samples a learner has seen, kept current by what the sensor sees.

Used by `GNGDT`'s rehearsal (``replay_share``): a moving camera shows one part of the world at a
time, so a network that learns only the current batch fits the view, not the world: nodes in
view follow the current batch, and a part out of view keeps what its last view made of it.
Drawing part of each batch's steps from this memory makes the network learn the world seen so
far. The memory is a uniform random sample of every sample
offered (reservoir sampling, Vitter's Algorithm R), less the samples a later view saw through
(the place is empty now): what vanished or moved is forgotten here as soon as the sensor looks.
Pure computation on arrays.
"""

from __future__ import annotations

import numpy as np

from gngdt.core.kernels.rehearsal import drop_marked
from gngdt.core.sensor.view import SensorView

#: the offered counter stops here (an int64, with room to spare): a uniform sample of 2**62
#: samples and of more is the same sample
MAX_OFFERED = 2**62


class SampleMemory:
    """Up to ``capacity`` samples in the model's frame.

    positions: (count, 3) float64 and colors: (count, 3) float64 (zeros without colours) are
    views of the stored samples; ``offered``: samples offered so far (Algorithm R's counter).
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self._positions = np.zeros((0, 3))
        self._colors = np.zeros((0, 3))
        self.count = 0
        self.offered = 0

    @property
    def positions(self) -> np.ndarray:
        return self._positions[: self.count]

    @property
    def colors(self) -> np.ndarray:
        return self._colors[: self.count]

    def restore(self, positions: np.ndarray, colors: np.ndarray, offered: int) -> None:
        """Set the stored samples ((M, 3) each, M <= capacity) and the offered counter."""
        self._grow(len(positions))
        self.count = len(positions)
        self._positions[: self.count] = positions
        self._colors[: self.count] = colors
        self.offered = max(int(offered), self.count)

    def offer(self, positions: np.ndarray, colors: np.ndarray | None,
              rng: np.random.Generator) -> None:
        """Offer samples (M, 3) (model frame; colours (M, 3) or None): free places are filled
        first, then the i-th sample ever offered replaces a random one with probability
        ``capacity / i``, so the memory stays a uniform sample of everything offered."""
        colors = np.zeros_like(positions) if colors is None else colors
        free = min(self.capacity - self.count, len(positions))
        if free > 0:
            self._grow(self.count + free)
            self._positions[self.count: self.count + free] = positions[:free]
            self._colors[self.count: self.count + free] = colors[:free]
            self.count += free
        rest = np.arange(free, len(positions))
        ordinal = self.offered + rest + 1
        kept = rest[rng.random(rest.size) * ordinal < self.capacity]
        if kept.size:
            slots = rng.integers(self.count, size=kept.size)  # a later sample wins a shared slot
            self._positions[slots] = positions[kept]
            self._colors[slots] = colors[kept]
        self.offered = min(self.offered + len(positions), MAX_OFFERED)

    def carve(self, view: SensorView, camera_from_model: np.ndarray, margin: float) -> int:
        """Drop the samples ``view`` saw through (see `SensorView.seen_through`); returns how
        many."""
        if self.count == 0:
            return 0
        through = view.seen_through(self._positions, self.count, camera_from_model, margin)
        count = self.count
        self.count = drop_marked(self._positions, self._colors, through, count)
        return count - self.count

    def draw(self, rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``count`` samples drawn with replacement: positions and colours, (count, 3) each."""
        rows = rng.integers(self.count, size=count)
        return self._positions[rows], self._colors[rows]

    def _grow(self, size: int) -> None:
        """Storage for at least ``size`` samples (grown geometrically up to the capacity)."""
        if size <= len(self._positions):
            return
        new_size = min(self.capacity, max(size, 2 * len(self._positions)))
        for name in ("_positions", "_colors"):
            grown = np.zeros((new_size, 3))
            grown[: self.count] = getattr(self, name)[: self.count]
            setattr(self, name, grown)
