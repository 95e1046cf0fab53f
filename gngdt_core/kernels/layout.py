"""The network's state as one bundle (`Network`) the kernels take whole, and the constants that
index its vectors.

All network state lives in preallocated arrays owned by the Python estimator
(`gngdt.core.gas.model`), bundled in a `Network` (a ``typing.NamedTuple``: numba takes it as one
argument and resolves each field at compile time); the kernels only read and write them, so a
learning step allocates nothing. `Network` documents each array's shape and dtype.

- A normal of (0, 0, 0) means "undefined" (fewer than two position neighbours, or a degenerate
  neighbourhood) and never gets a normal edge.
- Errors are stored *scaled*: true error = ``err * error_scale`` (Fišer et al. 2013), so the
  global decay of Step 9 is one multiplication of ``error_scale``.
- The adjacency has a fixed maximum degree ``K`` = ``MAX_DEGREE``; slots ``[0, deg[i])`` of row
  ``i`` are used. Degree overflow: if ``s1`` or ``s2`` already has ``K`` edges when Step 4 must
  create their edge, the edge is not created in that step (everything else proceeds); GNG degrees
  stay far below ``K`` in practice.
- Forgetting (GNG-U's utility, Fritzke 1997, judged only where the sensor can see): ``util`` is
  the error the network would gain without the node (for each sample a node wins, the squared
  distance to the second winner minus that to the winner), decaying by ``utility_decay`` per
  step (GNG-U2's chi, Toda et al. 2016) through its own lazy scale ``util_scale``. A node
  ``judged`` in the current call (one the sensor could see: in the view, not behind the measured
  surface) stores it scaled (true = ``util * util_scale``) and so decays; any other node stores
  it in true units, frozen, for the whole call. Every lambda steps the judged node of least
  utility is removed, with its edges, when ``max error > utility_k * its utility``. Utility
  counts only the current batch's samples (rows below ``iparams[Q_FRAME_ROWS]``), not those
  rehearsed from memory: it is what the sensor sees now.
- Persistent node ids: a node keeps its id while its index changes (deletion moves the last node
  into the hole); a new node takes ``istate[I_NEXT_ID]``, which then grows, so an id is never
  reused.
- The spatial hash grid for the winner search: a node's cell is ``floor(position * (1 /
  cell_size))`` per axis (the z cell is 0 in 2-D); every node in the grid is kept in the bucket
  of its current cell.

Nodes are deleted by swapping the last node into the hole, so indices stay compact.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

POS_BIT = 1
COL_BIT = 2
NOR_BIT = 4

MODE_GNGDT = 0
MODE_GNG = 1
MODE_GNGW = 2

MAX_DEGREE = 16

# indices into istate / fstate / fparams / iparams
I_NODES, I_STEPS, I_GRID, I_NEXT_ID, I_FORGOTTEN = 0, 1, 2, 3, 4
F_ERROR_SCALE, F_CELL, F_SPACING, F_UTIL_SCALE = 0, 1, 2, 3
P_ETA1, P_ETA2, P_ALPHA, P_BETA, P_TAU_COL, P_TAU_NOR, P_MU = 0, 1, 2, 3, 4, 5, 6
P_VX, P_VY, P_VZ, P_W_POS, P_W_COL, P_UTILITY_K, P_UTILITY_DECAY = 7, 8, 9, 10, 11, 12, 13
#: a sample farther than this from every node gets a node of its own (0: never; GNG-DT's
#: ``resolution_m``)
P_GROW_DISTANCE = 14
Q_LAMBDA, Q_AGE_MAX, Q_MAX_NODES, Q_MODE, Q_HAS_COL, Q_HAS_NOR, Q_ORIENT, Q_FORGET = range(8)
#: rows of ``samples`` from this index on are rehearsed (earlier batches'): no utility
Q_FRAME_ROWS = 8


class Network(NamedTuple):
    """The state of one network: every array the kernels read and write.

    ``cap`` = node capacity (``max_nodes``), ``D`` = 2 or 3 input dimensions, ``K`` =
    `MAX_DEGREE`, ``T`` = grid table size (a power of two); nodes ``0..n-1`` are in use
    (``n = istate[I_NODES]``).

    Attributes
    ----------
    pos : (cap, D) float64
        Node positions, in the input's units.
    col : (cap, 3) float64
        Node colours, on the input's scale (zeros when none are learned).
    nor : (cap, 3) float64
        Unit normals (eq. 16); (0, 0, 0) where undefined.
    err : (cap,) float64
        Accumulated errors, scaled: true error = ``err * fstate[F_ERROR_SCALE]``.
    nbr : (cap, K) int32
        Neighbour of each used edge slot.
    age : (cap, K) int32
        Age of each edge, the same in both of its slots.
    emask : (cap, K) uint8
        Properties the edge has (``POS_BIT`` always: the other topologies are subsets of the
        position edges; ``COL_BIT``, ``NOR_BIT``).
    rev : (cap, K) int32
        Slot of the same edge in the neighbour's row.
    deg : (cap,) int32
        Used slots of each row.
    ids : (cap,) int64
        Persistent node ids.
    util : (cap,) float64
        Utilities (forgetting): scaled by ``fstate[F_UTIL_SCALE]`` for judged nodes, true
        values for the others.
    judged : (cap,) uint8
        1 for the nodes the current batch judges (forgetting).
    wins : (cap,) float64
        Samples each node has won (with ``resolution_m``: a young node's rate is ``1 / wins``).
    ghead : (T,) int32
        First node of each grid bucket, -1 for none.
    gnext, gprev : (cap,) int32
        Doubly linked bucket lists, -1 at the ends.
    gbucket : (cap,) int64
        Bucket of each node, -1 when it is not in the grid.
    gcell : (cap, 3) int64
        Integer cell of each node in the grid.
    istate : (5,) int64
        [n_nodes, n_steps, grid_active, next_id, nodes_forgotten] (``I_*`` indices).
    fstate : (4,) float64
        [error_scale, cell_size, spacing_ema, util_scale] (``F_*`` indices).
    """

    pos: np.ndarray
    col: np.ndarray
    nor: np.ndarray
    err: np.ndarray
    nbr: np.ndarray
    age: np.ndarray
    emask: np.ndarray
    rev: np.ndarray
    deg: np.ndarray
    ids: np.ndarray
    util: np.ndarray
    judged: np.ndarray
    wins: np.ndarray
    ghead: np.ndarray
    gnext: np.ndarray
    gprev: np.ndarray
    gbucket: np.ndarray
    gcell: np.ndarray
    istate: np.ndarray
    fstate: np.ndarray

    @classmethod
    def allocate(cls, cap: int, dim: int, istate: np.ndarray | None = None,
                 fstate: np.ndarray | None = None) -> Network:
        """Zeroed arrays for ``cap`` nodes of ``dim`` (0, 2 or 3) dimensions, the grid empty;
        ``istate``/``fstate`` kept when given (a fresh model's counters otherwise)."""
        table = 1 << max(10, int(2 * cap - 1).bit_length())
        return cls(
            pos=np.zeros((cap, dim)), col=np.zeros((cap, 3)), nor=np.zeros((cap, 3)),
            err=np.zeros(cap),
            nbr=np.zeros((cap, MAX_DEGREE), dtype=np.int32),
            age=np.zeros((cap, MAX_DEGREE), dtype=np.int32),
            emask=np.zeros((cap, MAX_DEGREE), dtype=np.uint8),
            rev=np.zeros((cap, MAX_DEGREE), dtype=np.int32),
            deg=np.zeros(cap, dtype=np.int32), ids=np.zeros(cap, dtype=np.int64),
            util=np.zeros(cap), judged=np.zeros(cap, dtype=np.uint8), wins=np.zeros(cap),
            ghead=np.full(table, -1, dtype=np.int32), gnext=np.full(cap, -1, dtype=np.int32),
            gprev=np.full(cap, -1, dtype=np.int32), gbucket=np.full(cap, -1, dtype=np.int64),
            gcell=np.zeros((cap, 3), dtype=np.int64),
            istate=np.zeros(5, dtype=np.int64) if istate is None else istate,
            fstate=np.array([1.0, 0.0, 0.0, 1.0]) if fstate is None else fstate,
        )
