"""The learning loop of the growing-gas learners: one loop for GNG-DT, GNG and GNG-W.

Steps 1-9 per sample (`learn`), node insertion (Step 8) and forgetting (GNG-U's utility), on a
`layout.Network`; its arrays and the indices into the state and parameter vectors are described
in `layout`.

Speed notes: a step takes well under a microsecond, so the per-step loop (`_learn_steps`) runs
without numba's reference counting, its helpers are inlined at the numba IR level
(`_numba.inlined`), and samples and nodes are read by index, never through array views.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gngdt.core.kernels._numba import flush_tiny, prefetch_row
from gngdt.core.kernels.graph import add_edge, delete_node, find_slot, remove_edge
from gngdt.core.kernels.grid import (
    GRID_CELL_SPACINGS,
    GRID_CELL_TOLERANCE,
    GRID_MIN_NODES,
    _grid_insert_new,
    _move_toward,
    _node_sq_dist,
    grid_rebuild,
    nearest_two_brute,
    nearest_two_grid,
    nearest_two_weighted,
)
from gngdt.core.kernels.layout import (
    COL_BIT,
    F_CELL,
    F_ERROR_SCALE,
    F_SPACING,
    F_UTIL_SCALE,
    I_FORGOTTEN,
    I_GRID,
    I_NEXT_ID,
    I_NODES,
    I_STEPS,
    MODE_GNG,
    MODE_GNGDT,
    P_ALPHA,
    P_BETA,
    P_ETA1,
    P_ETA2,
    P_GROW_DISTANCE,
    P_MU,
    P_TAU_COL,
    P_TAU_NOR,
    P_UTILITY_DECAY,
    P_UTILITY_K,
    P_VX,
    P_VY,
    P_VZ,
    P_W_COL,
    P_W_POS,
    POS_BIT,
    Q_AGE_MAX,
    Q_FORGET,
    Q_FRAME_ROWS,
    Q_HAS_COL,
    Q_HAS_NOR,
    Q_LAMBDA,
    Q_MAX_NODES,
    Q_MODE,
    Q_ORIENT,
)
from gngdt.core.kernels.normals import _interpolate_normal, compute_normal, property_bits

# Renormalise stored errors when the global decay factor falls below this.
ERROR_SCALE_FLOOR = 1e-60
# Steps between naming a sample's row to the cache (`prefetch_row`) and learning it.
PREFETCH_AHEAD = 2


@njit(cache=True, nogil=True)  # the tracker thread tracks meanwhile
def learn(samples, sample_colors, order, net, fparams, iparams):
    """Run one learning step (Steps 1-9) of ``net`` per index in ``order`` (rows of ``samples``).

    Parameters
    ----------
    samples : (N, D) float64
        Positions, in the network's frame.
    sample_colors : (N, 3) float64
        Their colours, or any (1, 3) placeholder without colour (then never read).
    order : (M,) int64
        Rows of ``samples`` to learn, one step each, in this order.
    net : layout.Network
        The network, changed in place. With forgetting on, ``net.judged`` marks the nodes the
        sensor could see in this call (see `layout`); nodes inserted during it are judged.
    fparams : (15,) float64
        The float parameters (``P_*`` indices in `layout`).
    iparams : (9,) int64
        The integer parameters (``Q_*`` indices in `layout`).
    """
    # scratch for Step 7 (the neighbours whose edge to s1 just expired) and for forgetting (a
    # node and its neighbours)
    candidates = np.empty(net.nbr.shape[1] + 1, dtype=np.int64)
    forget = iparams[Q_FORGET] != 0
    if forget:  # utilities of the nodes not judged now: frozen, in true units, for this call
        _rescale_unjudged(net, net.fstate[F_UTIL_SCALE])
    _learn_steps(samples, sample_colors, order, net, fparams, iparams, candidates)
    if forget:
        _rescale_unjudged(net, 1.0 / net.fstate[F_UTIL_SCALE])


@njit(cache=True)
def _rescale_unjudged(net, factor):
    """Multiply the utility of every node not judged now by ``factor``."""
    for i in range(net.istate[I_NODES]):
        if net.judged[i] == 0:
            net.util[i] *= factor


@njit(cache=True)
def forget_least_useful(net, n, error_scale, util_scale, utility_k, candidates):
    """GNG-U's removal among the judged nodes of the ``n`` in use: the judged node ``l`` of
    least utility goes, with its edges and any neighbour left without one, when ``max error >
    utility_k * U_l`` (true, unscaled values). ``candidates``: (MAX_DEGREE + 1,) int64 scratch.
    Returns (new n, nodes removed).
    """
    err = net.err
    util = net.util
    judged = net.judged
    deg = net.deg
    max_err = 0.0
    least = -1
    least_util = np.inf
    for i in range(n):
        if err[i] > max_err:
            max_err = err[i]
        if judged[i] != 0 and util[i] < least_util:
            least_util = util[i]
            least = i
    if least < 0 or n <= 2 or not max_err * error_scale > utility_k * least_util * util_scale:
        return n, 0
    n_candidates = 0
    while deg[least] > 0:
        k = deg[least] - 1
        candidates[n_candidates] = net.nbr[least, k]
        n_candidates += 1
        remove_edge(net, least, k)
    candidates[n_candidates] = least
    n_candidates += 1
    removed = 0
    for q in range(n_candidates):
        j = candidates[q]
        if deg[j] == 0 and n > 2:
            last = delete_node(net, j, n)
            n -= 1
            removed += 1
            for q2 in range(q + 1, n_candidates):
                if candidates[q2] == last:
                    candidates[q2] = j
    return n, removed


# Compiled without the numba runtime (``_nrt=False``, the option numba uses for its own hot
# helpers): every array here is owned by the caller, so the atomic reference counting that numba
# would otherwise emit around each inlined helper is pure overhead (it cost ~40% of a step).
# Without the runtime the function cannot allocate; numba refuses to compile it if it tries.
@njit(cache=True, _nrt=False)
def _learn_steps(samples, sample_colors, order, net, fparams, iparams, candidates):
    """The body of `learn`; ``candidates`` (MAX_DEGREE + 1,) int64 scratch."""
    pos = net.pos
    col = net.col
    err = net.err
    nbr = net.nbr
    age = net.age
    emask = net.emask
    rev = net.rev
    deg = net.deg
    ids = net.ids
    util = net.util
    judged = net.judged
    wins = net.wins
    istate = net.istate
    fstate = net.fstate
    eta1 = fparams[P_ETA1]
    eta2 = fparams[P_ETA2]
    alpha = fparams[P_ALPHA]
    beta = fparams[P_BETA]
    tau_col = fparams[P_TAU_COL]
    tau_nor = fparams[P_TAU_NOR]
    mu = fparams[P_MU]
    vx = fparams[P_VX]
    vy = fparams[P_VY]
    vz = fparams[P_VZ]
    w_pos = fparams[P_W_POS]
    w_col = fparams[P_W_COL]
    lam = iparams[Q_LAMBDA]
    age_max = iparams[Q_AGE_MAX]
    max_nodes = iparams[Q_MAX_NODES]
    mode = iparams[Q_MODE]
    has_col = iparams[Q_HAS_COL] != 0
    has_nor = iparams[Q_HAS_NOR] != 0
    orient = iparams[Q_ORIENT] != 0
    forget = iparams[Q_FORGET] != 0
    frame_rows = iparams[Q_FRAME_ROWS]
    utility_k = fparams[P_UTILITY_K]
    utility_decay = fparams[P_UTILITY_DECAY]
    grow_sq = fparams[P_GROW_DISTANCE] * fparams[P_GROW_DISTANCE]
    # in GNG / GNG-W colour is part of the input vector and follows the single topology
    col_follows_pos = mode != MODE_GNGDT
    # winners by position alone: GNG-DT, and GNG without colour (its distance is then the same),
    # which search the grid once it is worth it
    by_position = mode == MODE_GNGDT or (mode == MODE_GNG and not has_col)

    n = istate[I_NODES]
    t = istate[I_STEPS]
    next_id = istate[I_NEXT_ID]
    forgotten = istate[I_FORGOTTEN]
    grid_on = istate[I_GRID] != 0
    error_scale = fstate[F_ERROR_SCALE]
    util_scale = fstate[F_UTIL_SCALE]
    cell_size = fstate[F_CELL]
    inv_cell = 1.0 / cell_size if grid_on else 0.0
    spacing = fstate[F_SPACING]
    dim = pos.shape[1]
    # steps since the last Step 8 (t % lam, counted instead of divided each step)
    phase = t % lam

    n_order = order.shape[0]
    for q in range(n_order):
        # the samples are visited in a random order: name the row PREFETCH_AHEAD steps on now,
        # so that it is in the cache when its step reads it (a miss cost ~30% of a step)
        if q + PREFETCH_AHEAD < n_order:
            ahead = order[q + PREFETCH_AHEAD]
            prefetch_row(samples, ahead)
            if has_col:
                prefetch_row(sample_colors, ahead)
        idx = order[q]
        x0 = samples[idx, 0]
        x1 = samples[idx, 1]
        x2 = samples[idx, 2] if dim > 2 else 0.0
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        if has_col:  # without colour, sample_colors is a (1, 3) placeholder: never index it
            c0 = sample_colors[idx, 0]
            c1 = sample_colors[idx, 1]
            c2 = sample_colors[idx, 2]
        t += 1
        phase += 1
        if phase == lam:
            phase = 0
        # Step 2 (and the error of Step 3)
        if by_position:
            if grid_on:
                s1, s2, err_add, second = nearest_two_grid(net, n, x0, x1, x2, dim, cell_size,
                                                           inv_cell)
            else:
                s1, s2, err_add, second = nearest_two_brute(pos, n, x0, x1, x2, dim)
        else:
            s1, s2, err_add = nearest_two_weighted(pos, col, n, x0, x1, x2, dim, c0, c1, c2,
                                                   mode, has_col, w_pos, w_col)
            second = err_add
        if s2 < 0:  # every distance overflowed (|x| ~ 1e154): no winner, learn nothing
            continue
        # new surface (``resolution_m``): a sample farther than the resolution from every node
        # gets a node at its place, joined to its winner (as Marsland et al.'s GWR grows)
        if (grow_sq > 0.0 and err_add > grow_sq and n < max_nodes and mode == MODE_GNGDT
                and deg[s1] < nbr.shape[1]):
            n = _insert_at_sample(net, n, s1, x0, x1, x2, c0, c1, c2, has_col, has_nor,
                                  tau_col, tau_nor, forget, util_scale)
            ids[n - 1] = next_id
            next_id += 1
            if grid_on:
                _grid_insert_new(net, n - 1, inv_cell)
        # Step 3
        err[s1] += err_add / error_scale
        # GNG-U: what the network would lose without s1, by what the sensor sees now
        if forget and judged[s1] != 0 and idx < frame_rows:
            util[s1] += (second - err_add) / util_scale
        # running node spacing (distance between winners) sizes the grid cells
        d12 = math.sqrt(_node_sq_dist(pos, s1, s2))
        if spacing <= 0.0:
            spacing = d12
        else:
            spacing += 0.01 * (d12 - spacing)
        # Step 4
        k12 = find_slot(net, s1, s2)
        if k12 < 0:
            if add_edge(net, s1, s2, POS_BIT):
                k12 = deg[s1] - 1
        if k12 >= 0:
            mask = property_bits(net, s1, s2, has_col, has_nor, tau_col, tau_nor)
            age[s1, k12] = 0
            emask[s1, k12] = mask
            k21 = rev[s1, k12]
            age[s2, k21] = 0
            emask[s2, k21] = mask
        # Step 5: the winner moves in every input property (with ``resolution_m``, a young node
        # at the mean of the samples it won, as online k-means places a centre, until eta1) ...
        rate = eta1
        if grow_sq > 0.0:
            wins[s1] += 1.0
            rate = max(eta1, 1.0 / wins[s1])
        _move_toward(net, s1, x0, x1, x2, dim, rate, grid_on, inv_cell)
        if has_col:
            col[s1, 0] = flush_tiny(col[s1, 0] + rate * (c0 - col[s1, 0]))
            col[s1, 1] = flush_tiny(col[s1, 1] + rate * (c1 - col[s1, 1]))
            col[s1, 2] = flush_tiny(col[s1, 2] + rate * (c2 - col[s1, 2]))
        # ... each neighbour in property o only along an edge of o. Step 6: ages.
        for k in range(deg[s1]):
            j = nbr[s1, k]
            _move_toward(net, j, x0, x1, x2, dim, eta2, grid_on, inv_cell)
            if has_col and (col_follows_pos or (emask[s1, k] & COL_BIT) != 0):
                col[j, 0] = flush_tiny(col[j, 0] + eta2 * (c0 - col[j, 0]))
                col[j, 1] = flush_tiny(col[j, 1] + eta2 * (c1 - col[j, 1]))
                col[j, 2] = flush_tiny(col[j, 2] + eta2 * (c2 - col[j, 2]))
            age[s1, k] += 1
            age[j, rev[s1, k]] += 1
        # Step 7: delete old edges of s1, then nodes left without position edges
        n_candidates = 0
        k = 0
        while k < deg[s1]:
            if age[s1, k] > age_max:
                candidates[n_candidates] = nbr[s1, k]
                n_candidates += 1
                remove_edge(net, s1, k)
            else:
                k += 1
        for q in range(n_candidates):
            j = candidates[q]
            if deg[j] == 0:
                last = delete_node(net, j, n)
                n -= 1
                if s1 == last:
                    s1 = j
                for q2 in range(q + 1, n_candidates):
                    if candidates[q2] == last:
                        candidates[q2] = j
        if deg[s1] == 0:
            delete_node(net, s1, n)
            n -= 1
        elif has_nor:
            compute_normal(net, s1, mu, orient, vx, vy, vz)
        # Step 8: insertion every lambda steps, until max_nodes
        if phase == 0:
            if forget:
                n, removed = forget_least_useful(net, n, error_scale, util_scale, utility_k,
                                                 candidates)
                forgotten += removed
            if n < max_nodes:
                n = _insert_node(net, n, has_col, has_nor, tau_col, tau_nor, alpha, orient, vx,
                                 vy, vz, forget, util_scale)
                ids[n - 1] = next_id
                next_id += 1
                if grid_on:
                    _grid_insert_new(net, n - 1, inv_cell)
            # keep grid cells about GRID_CELL_SPACINGS node spacings wide (amortised O(n) per
            # lambda steps); the cell size only affects speed, never the winners found
            target_cell = GRID_CELL_SPACINGS * spacing
            if by_position and n >= GRID_MIN_NODES and spacing > 0.0 and (
                not grid_on
                or cell_size > GRID_CELL_TOLERANCE * target_cell
                or target_cell > GRID_CELL_TOLERANCE * cell_size
            ):
                cell_size = target_cell
                inv_cell = 1.0 / cell_size
                grid_rebuild(net, n, cell_size)
                grid_on = True
        # Step 9, lazily: true error = stored error * error_scale
        error_scale *= 1.0 - beta
        if error_scale < ERROR_SCALE_FLOOR:
            for i in range(n):
                err[i] *= error_scale
            error_scale = 1.0
        if forget:  # the judged nodes' utilities decay (the others are frozen, in true units)
            util_scale *= 1.0 - utility_decay
            if util_scale < ERROR_SCALE_FLOOR:
                for i in range(n):
                    if judged[i] != 0:
                        util[i] *= util_scale
                util_scale = 1.0

    istate[I_NODES] = n
    istate[I_STEPS] = t
    istate[I_GRID] = 1 if grid_on else 0
    istate[I_NEXT_ID] = next_id
    istate[I_FORGOTTEN] = forgotten
    fstate[F_ERROR_SCALE] = error_scale
    fstate[F_UTIL_SCALE] = util_scale
    fstate[F_CELL] = cell_size
    fstate[F_SPACING] = spacing


@njit(cache=True)
def _insert_at_sample(net, n, s1, x0, x1, x2, c0, c1, c2, has_col, has_nor, tau_col, tau_nor,
                      forget, util_scale):
    """A new node at the sample (x0, x1[, x2]) with its colour, joined to the winner ``s1``
    by an edge; it takes the winner's normal, error and (judged) utility. Returns n + 1."""
    pos = net.pos
    col = net.col
    util = net.util
    judged = net.judged
    r = n
    pos[r, 0] = x0
    pos[r, 1] = x1
    if pos.shape[1] > 2:
        pos[r, 2] = x2
    col[r, 0] = c0 if has_col else col[s1, 0]
    col[r, 1] = c1 if has_col else col[s1, 1]
    col[r, 2] = c2 if has_col else col[s1, 2]
    for a in range(3):
        net.nor[r, a] = net.nor[s1, a]
    net.deg[r] = 0
    add_edge(net, s1, r, property_bits(net, s1, r, has_col, has_nor, tau_col, tau_nor))
    net.err[r] = net.err[s1]
    net.wins[r] = 1.0  # it stands for the one sample it was placed on
    if forget:
        util[r] = util[s1] if judged[s1] != 0 else util[s1] / util_scale
        judged[r] = 1
    return n + 1


@njit(cache=True)
def _insert_node(net, n, has_col, has_nor, tau_col, tau_nor, alpha, orient, vx, vy, vz, forget,
                 util_scale):
    """Step 8 i-vi: a new node ``n`` halfway between the max-error node and its max-error
    neighbour. Returns n + 1.

    With forgetting, the new node is judged and takes the mean utility of the two (GNG-U).
    """
    pos = net.pos
    col = net.col
    err = net.err
    nbr = net.nbr
    util = net.util
    judged = net.judged
    u = 0
    for i in range(1, n):
        if err[i] > err[u]:
            u = i
    ku = 0
    for k in range(1, net.deg[u]):
        if err[nbr[u, k]] > err[nbr[u, ku]]:
            ku = k
    f = nbr[u, ku]
    r = n
    for a in range(pos.shape[1]):
        pos[r, a] = 0.5 * (pos[u, a] + pos[f, a])
    for a in range(3):
        col[r, a] = 0.5 * (col[u, a] + col[f, a])
    _interpolate_normal(net, u, f, r, orient, vx, vy, vz)
    net.deg[r] = 0
    remove_edge(net, u, ku)
    add_edge(net, u, r, property_bits(net, u, r, has_col, has_nor, tau_col, tau_nor))
    add_edge(net, r, f, property_bits(net, r, f, has_col, has_nor, tau_col, tau_nor))
    err[u] -= alpha * err[u]
    err[f] -= alpha * err[f]
    err[r] = 0.5 * (err[u] + err[f])
    net.wins[r] = 1.0
    if forget:
        scaled_u = util[u] if judged[u] != 0 else util[u] / util_scale
        scaled_f = util[f] if judged[f] != 0 else util[f] / util_scale
        util[r] = 0.5 * (scaled_u + scaled_f)
        judged[r] = 1
    return n + 1
