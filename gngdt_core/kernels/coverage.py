"""Kernels of the surface a sensor has seen (`gngdt.core.gas.coverage`): a hash set of the cubic
cells, ``cell`` metres wide, that points fell in, as an open-addressing table of int64 keys.

A cell's key packs its three integer coordinates, each offset by ``KEY_OFFSET`` into 21 bits
(cells within about a million cells of the origin: 10 km at 1 cm); ``EMPTY`` marks a free slot.
Tables are powers of two in size and kept at most half full by the caller (`mark_cells` stops
when the next insertion would pass ``max_count``, `rehash` moves every key to a larger table).
Pure functions over arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import inlined

EMPTY = -1
KEY_BITS = 21
KEY_OFFSET = 1 << (KEY_BITS - 1)
_KEY_MASK = (1 << KEY_BITS) - 1
#: Fibonacci hashing's multiplier (2^64 / golden ratio), as a signed int64
_GOLDEN = np.int64(-7046029254386353131)


@inlined
def _slot(key, shift, mask):
    # the product's top bits: each of them depends on every bit of the key, where a low bit of
    # the product depends only on the key's lower bits (with bits 17-28, the slot ignored x and
    # most of y: 36 probes an insertion, 80 ns a point)
    return (key * _GOLDEN >> shift) & mask


@inlined
def _top_shift(slots):
    """The shift that leaves log2(``slots``) bits of a 64-bit product."""
    bits = 0
    while (1 << bits) < slots:
        bits += 1
    return 64 - bits


@njit(cache=True)
def mark_cells(points, rotation, translation, inv_cell, keys, count, max_count, start):
    """Insert the cells of ``points[start:]`` into ``keys``; returns (cells now in the table,
    the row it stopped at: ``len(points)`` when done, earlier when the table reached
    ``max_count`` and must grow first).

    points: (M, 3) float32/float64, mapped by ``rotation`` (3, 3) and ``translation`` (3,)
    into the frame the cells are in (the model's); rows with a non-finite coordinate are
    skipped. keys: (T,) int64, T a power of two, ``EMPTY`` where free.
    """
    mask = keys.shape[0] - 1
    shift = _top_shift(keys.shape[0])
    last = EMPTY
    for row in range(start, points.shape[0]):
        if count >= max_count:
            return count, row
        key = 0
        finite = True
        for a in range(3):
            value = (rotation[a, 0] * points[row, 0] + rotation[a, 1] * points[row, 1]
                     + rotation[a, 2] * points[row, 2] + translation[a])
            if not np.isfinite(value):
                finite = False
                break
            index = np.int64(np.floor(value * inv_cell)) + KEY_OFFSET
            key = (key << KEY_BITS) | (index & _KEY_MASK)
        if not finite or key == last:  # neighbouring pixels often share a cell
            continue
        last = key
        slot = _slot(key, shift, mask)
        while keys[slot] != EMPTY and keys[slot] != key:
            slot = (slot + 1) & mask
        if keys[slot] == EMPTY:
            keys[slot] = key
            count += 1
    return count, points.shape[0]


@njit(cache=True)
def rehash(old_keys, new_keys):
    """Move every key of ``old_keys`` into the empty table ``new_keys`` (a power of two)."""
    mask = new_keys.shape[0] - 1
    shift = _top_shift(new_keys.shape[0])
    for key in old_keys:
        if key == EMPTY:
            continue
        slot = _slot(key, shift, mask)
        while new_keys[slot] != EMPTY:
            slot = (slot + 1) & mask
        new_keys[slot] = key


def cell_centres(keys: np.ndarray, cell: float) -> np.ndarray:
    """(K, 3) float64 centres (metres) of the cells whose keys are ``keys`` (K,) (no EMPTY)."""
    keys = np.asarray(keys, dtype=np.int64)
    indices = np.stack([(keys >> (KEY_BITS * (2 - a))) & _KEY_MASK for a in range(3)], axis=1)
    return (indices - KEY_OFFSET + 0.5) * cell
