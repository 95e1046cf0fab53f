"""The arrays the kernels share and the constants that index them.

All network state lives in preallocated arrays owned by the Python estimator
(`gngdt.core.gas.model`); the kernels only read and write them, so a learning step allocates
nothing.

Layout (``cap`` = node capacity = ``max_nodes``, ``K`` = ``MAX_DEGREE``):

- ``pos`` (cap, D) float64, ``col`` (cap, 3) float64, ``nor`` (cap, 3) float64 node properties;
  a normal of (0, 0, 0) means "undefined" (fewer than two position neighbours, or a degenerate
  neighbourhood) and never gets a normal edge.
- ``err`` (cap,) float64 accumulated errors stored *scaled*: true error = ``err * error_scale``
  (Fišer et al. 2013), so the global decay of Step 9 is one multiplication of ``error_scale``.
- Adjacency with a fixed maximum degree: ``nbr`` (cap, K) int32 neighbour index, ``age`` (cap, K)
  int32, ``emask`` (cap, K) uint8 bitmask of the properties the edge has (``POS_BIT`` always set:
  edges of other properties are a subset of the position edges), ``rev`` (cap, K) int32 the slot
  of the same edge in the neighbour's row, ``deg`` (cap,) int32. Slots ``[0, deg[i])`` are used.
  Degree overflow: if ``s1`` or ``s2`` already has ``K`` edges when Step 4 must create their edge,
  the edge is not created in that step (everything else proceeds); GNG degrees stay far below
  ``K`` in practice.
- Forgetting (GNG-U's utility, Fritzke 1997, judged only where the sensor can see): ``util``
  (cap,) float64 utility, the error the network would gain without the node (for each sample a
  node wins, the squared distance to the second winner minus that to the winner), decaying by
  ``utility_decay`` per step (GNG-U2's chi, Toda et al. 2016) through its own lazy scale
  ``util_scale``. A node ``judged`` (cap,) uint8 in the current call (one the sensor could see:
  in the view, not behind the measured surface) stores it scaled (true = ``util * util_scale``)
  and so decays; any other node stores it in true units, frozen, for the whole call. Every lambda
  steps the judged node of least utility is removed, with its edges, when ``max error >
  utility_k * its utility``. Utility counts only the current batch's samples (rows below
  ``iparams[Q_FRAME_ROWS]``), not those rehearsed from memory: it is what the sensor sees now.
- ``ids`` (cap,) int64 persistent node ids: a node keeps its id while its index changes (deletion
  moves the last node into the hole); a new node takes ``istate[I_NEXT_ID]``, which then grows, so
  an id is never reused.
- Spatial hash grid for the winner search: ``ghead`` (T,) int32 first node of each bucket,
  ``gnext``/``gprev`` (cap,) int32 doubly linked bucket lists, ``gbucket`` (cap,) int64 bucket of
  each node (-1: not in the grid), ``gcell`` (cap, 3) int64 integer cell of each node. A node's
  cell is ``floor(position * (1 / cell_size))`` per axis (the z cell is 0 in 2-D); every node
  in the grid is kept in the bucket of its current cell.
- ``istate`` int64: [n_nodes, n_steps, grid_active, next_id, nodes_forgotten]; ``fstate``
  float64: [error_scale, cell_size, spacing_ema, util_scale].

Nodes are deleted by swapping the last node into the hole, so indices stay compact.
"""

from __future__ import annotations

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
