"""A learner's state as numpy arrays (`snapshot`, behind `get_state()`) and a learner rebuilt
from them (`restore`, behind `from_state()`), with every consistency check in one place."""

from __future__ import annotations

import json
from typing import Any, TypeVar

import numpy as np

from gngdt.core.clustering import COL, NOR, POS
from gngdt.core.gas.sampling import checked_pose
from gngdt.core.kernels import layout as K
from gngdt.core.kernels.grid import grid_rebuild

Model = TypeVar("Model")

STATE_VERSION = 5  # 2: persistent node ids (``ids``, a fourth counter); 3: utility (``util``,
# a fifth counter: nodes forgotten); 4: the rehearsal memory (``memory_*``); 5: the surface
# seen (``coverage_cells``, with ``resolution_m``) and each node's wins (``wins``)

#: largest counter (steps, node ids, samples offered, ...) a state may hold: far below 2**63,
#: so that the counters can go on counting for ever without overflowing an int64
MAX_STATE_COUNTER = 2**62
#: a node normal is a unit vector (or zero before it is estimated); float32 rounding aside
NORMAL_TOLERANCE = 1e-3
#: float dtypes of a state's arrays (float16 loses what was learned; others are not ours)
_FLOAT_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))

#: the network's arrays a state holds (the rows in use), by their `kernels.layout.Network`
#: field names: float arrays (the node properties are named as their topologies, the format's
#: keys since version 1), then the adjacency, then those that older states may lack
_FLOAT_ARRAYS = (POS, COL, NOR, "err")
_INT_ARRAYS = ("nbr", "age", "emask", "rev", "deg")
_SAVED_ARRAYS = (*_FLOAT_ARRAYS, *_INT_ARRAYS, "ids", "util", "wins")


def snapshot(model: Any) -> dict[str, np.ndarray]:
    """Everything needed to continue ``model`` (a `GrowingGas`) exactly, as numpy arrays only
    (np.savez-safe)."""
    n = model.n_nodes_
    net = model._network
    params = model._settings
    # an unfitted model draws nothing before its first batch: a generator as fit would seed it
    rng = model._rng if model._rng is not None else np.random.default_rng(params["random_state"])
    state: dict[str, np.ndarray] = {
        "model": np.array(type(model).__name__),
        "version": np.array(STATE_VERSION, dtype=np.int64),
        "params": np.array(json.dumps(params)),
        "rng_state": np.array(json.dumps(rng.bit_generator.state)),
        "dim": np.array(model._dim, dtype=np.int64),
        "has_colors": np.array(int(model._has_col), dtype=np.int64),
        "n_invalid": np.array(model.n_invalid_, dtype=np.int64),
        "counters": model._istate.copy(),
        "scalars": model._fstate.copy(),
    }
    if model._camera_pose is not None:  # the last batch's pose places the viewpoint
        state["camera_pose"] = model._camera_pose.copy()
    if model._memory is not None:
        state["memory_positions"] = model._memory.positions.copy()
        state["memory_colors"] = model._memory.colors.copy()
        state["memory_offered"] = np.array(model._memory.offered, dtype=np.int64)
    if model._coverage is not None:
        state["coverage_cells"] = model._coverage.cells()
    if model._dim:  # an unfitted model has no node arrays
        for name in _SAVED_ARRAYS:
            state[name] = getattr(net, name)[:n].copy()
    return state


def _scalar_text(state: dict[str, np.ndarray], key: str) -> str:
    value = np.asarray(state[key])
    if value.shape != () or value.dtype.kind != "U":
        raise ValueError(
            f"state[{key!r}] must be a 0-d string array, got {value.dtype} {value.shape}"
        )
    return str(value[()])


def _scalar_int(state: dict[str, np.ndarray], key: str) -> int:
    value = np.asarray(state[key])
    if value.shape != () or value.dtype.kind not in "iu":
        raise ValueError(
            f"state[{key!r}] must be a 0-d integer array, got {value.dtype} {value.shape}"
        )
    return int(value)


def _array(state: dict[str, np.ndarray], key: str, shape: tuple[int, ...], kind: str) -> np.ndarray:
    value = np.asarray(state[key])
    if value.shape != shape:
        raise ValueError(f"state[{key!r}] has shape {value.shape}, expected {shape}")
    if value.dtype.kind not in kind:
        raise ValueError(f"state[{key!r}] has dtype {value.dtype}, expected kind {kind!r}")
    if value.dtype.kind == "f" and value.dtype not in _FLOAT_DTYPES:
        raise ValueError(f"state[{key!r}] has dtype {value.dtype}, expected float32 or float64")
    return value


def restore(cls: type[Model], state: dict[str, np.ndarray]) -> Model:
    """Build a ``cls`` learner from ``state``; ValueError naming the first inconsistency."""
    required = ("model", "params", "rng_state", "dim", "has_colors", "n_invalid", "counters",
                "scalars")
    missing = [key for key in required if key not in state]
    if missing:
        raise ValueError(f"state is missing {missing}")
    name = _scalar_text(state, "model")
    if name != cls.__name__:
        raise ValueError(f"state holds a {name} model, not a {cls.__name__}")
    if "version" in state:  # states saved before versions had none
        version = _scalar_int(state, "version")
        if not 1 <= version <= STATE_VERSION:
            raise ValueError(f"state version {version}; this gngdt reads versions "
                             f"1..{STATE_VERSION}")
    try:
        params: dict[str, Any] = json.loads(_scalar_text(state, "params"))
        rng_state = json.loads(_scalar_text(state, "rng_state"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"state params/rng_state are not valid JSON: {exc}") from exc
    if not isinstance(params, dict):
        raise ValueError(f"state params must be a JSON object, got {type(params).__name__}")
    unknown = set(params) - set(cls._get_param_names())
    if unknown:
        raise ValueError(f"state params has unknown parameters {sorted(unknown)}")
    model = cls(**params)
    model._start(model.check_params())
    try:
        model._rng.bit_generator.state = rng_state
    except (TypeError, ValueError, KeyError) as exc:
        raise ValueError(f"state rng_state is not a {type(model._rng.bit_generator).__name__} "
                         f"state: {exc}") from exc

    dim = _scalar_int(state, "dim")
    has_col = _scalar_int(state, "has_colors")
    n_invalid = _scalar_int(state, "n_invalid")
    counters = _counters(state)
    scalars = _scalars(state)
    if dim not in (0, 2, 3):
        raise ValueError(f"state dim must be 0 (unfitted), 2 or 3, got {dim}")
    if has_col not in (0, 1) or not 0 <= n_invalid <= MAX_STATE_COUNTER:
        raise ValueError("state has_colors must be 0/1 and n_invalid in 0..2**62")
    n = int(counters[K.I_NODES])
    if counters[K.I_STEPS] < 0 or counters[K.I_GRID] not in (0, 1):
        raise ValueError(f"state counters are invalid: {counters.tolist()}")
    if not np.isfinite(scalars).all() or scalars[K.F_ERROR_SCALE] <= 0.0:
        raise ValueError(f"state scalars are invalid: {scalars.tolist()}")
    model.n_invalid_ = n_invalid
    if dim == 0:
        if n != 0:
            raise ValueError(f"state has {n} nodes but no dimension")
        return model
    if not (2 <= n <= model._params["max_nodes"]):
        raise ValueError(f"state has {n} nodes; expected 2..max_nodes={model._params['max_nodes']}")
    if counters[K.I_GRID] and scalars[K.F_CELL] <= 0.0:
        raise ValueError("state has an active grid with a non-positive cell size")

    arrays = _node_arrays(state, n, dim, counters)
    model._allocate(dim, bool(has_col))
    net = model._network
    for key, value in arrays.items():
        getattr(net, key)[:n] = value
    net.istate[:] = counters
    net.fstate[:] = scalars
    if "camera_pose" in state:  # states saved before camera poses: the camera frame
        model._camera_pose = checked_pose(_array(state, "camera_pose", (4, 4), "f"), dim)
    if model._memory is not None:  # states saved before rehearsal: an empty memory
        _restore_memory(model._memory, state)
    if model._coverage is not None and "coverage_cells" in state:  # else: none seen yet
        model._coverage.restore(state["coverage_cells"])
    if counters[K.I_GRID]:
        grid_rebuild(net, n, float(scalars[K.F_CELL]))
    return model


def _node_arrays(state: dict[str, np.ndarray], n: int, dim: int,
                 counters: np.ndarray) -> dict[str, np.ndarray]:
    """The ``n`` nodes' arrays of ``state``, checked (shapes, finite, a symmetric adjacency);
    sets ``counters[I_NEXT_ID]`` when the state predates node ids (see `_node_ids`)."""
    shapes = {POS: (n, dim), COL: (n, 3), NOR: (n, 3), "err": (n,), "deg": (n,)}
    for key in _FLOAT_ARRAYS + _INT_ARRAYS:
        if key not in state:
            raise ValueError(f"state is missing {key!r}")
    arrays = {key: _array(state, key, shapes.get(key, (n, K.MAX_DEGREE)),
                          "f" if key in _FLOAT_ARRAYS else "iu")
              for key in _FLOAT_ARRAYS + _INT_ARRAYS}
    for key in _FLOAT_ARRAYS:
        if not np.isfinite(arrays[key]).all():
            raise ValueError(f"state[{key!r}] contains NaN or inf")
    if (arrays["err"] < 0).any():
        raise ValueError("state['err'] must be non-negative (accumulated squared distances)")
    if (np.linalg.norm(arrays[NOR], axis=1) > 1.0 + NORMAL_TOLERANCE).any():
        raise ValueError("state['nor'] holds vectors longer than a unit normal")
    _check_adjacency(n, arrays)
    arrays["ids"], counters[K.I_NEXT_ID] = _node_ids(state, n, int(counters[K.I_NEXT_ID]))
    # states saved before win counts: every node mature (a young node's rate is 1 / wins)
    arrays["wins"] = np.full(n, 1e9)
    if "wins" in state:
        arrays["wins"] = _array(state, "wins", (n,), "f").astype(np.float64)
        if not np.isfinite(arrays["wins"]).all() or (arrays["wins"] < 0).any():
            raise ValueError("state['wins'] must be finite and non-negative")
    arrays["util"] = np.zeros(n)  # states saved before forgetting existed: no utility yet
    if "util" in state:
        arrays["util"] = _array(state, "util", (n,), "f").astype(np.float64)
        if not np.isfinite(arrays["util"]).all() or (arrays["util"] < 0).any():
            raise ValueError("state['util'] must be finite and non-negative")
    return arrays


def _restore_memory(memory: Any, state: dict[str, np.ndarray]) -> None:
    """The rehearsal memory's samples and counter, when the state has them."""
    if "memory_positions" not in state:
        return
    missing = [key for key in ("memory_colors", "memory_offered") if key not in state]
    if missing:
        raise ValueError(f"state has memory_positions but is missing {missing}")
    positions = np.asarray(state["memory_positions"])
    count = positions.shape[0] if positions.ndim == 2 else -1
    if not 0 <= count <= memory.capacity:
        raise ValueError(f"state['memory_positions'] has shape {positions.shape}, expected "
                         f"(M, 3) with M <= replay_points={memory.capacity}")
    positions = _array(state, "memory_positions", (count, 3), "f")
    colors = _array(state, "memory_colors", (count, 3), "f")
    offered = _scalar_int(state, "memory_offered")
    if (not (np.isfinite(positions).all() and np.isfinite(colors).all())
            or not count <= offered <= MAX_STATE_COUNTER):
        raise ValueError("state memory must be finite, with memory_offered from its samples "
                         "to 2**62")
    memory.restore(positions, colors, offered)


def _scalars(state: dict[str, np.ndarray]) -> np.ndarray:
    """(4,) float64 [error_scale, cell_size, spacing, util_scale]; states saved before
    forgetting had three (util_scale = 1)."""
    scalars = np.asarray(state["scalars"])
    if scalars.shape not in ((3,), (4,)) or scalars.dtype.kind != "f":
        raise ValueError(f"state['scalars'] has {scalars.dtype} {scalars.shape}, "
                         "expected 3 or 4 floats")
    full = np.ones(4)
    full[: scalars.size] = scalars
    if not full[K.F_UTIL_SCALE] > 0.0:
        raise ValueError(f"state scalars are invalid: {full.tolist()}")
    return full


def _counters(state: dict[str, np.ndarray]) -> np.ndarray:
    """(5,) int64 [n_nodes, n_steps, grid_active, next_id, nodes_forgotten]; states saved
    before node ids had three counters, and get next_id = -1 here (fresh ids are assigned by
    `_node_ids`); states saved before forgetting had four, and have forgotten nothing."""
    counters = np.asarray(state["counters"])
    if counters.shape not in ((3,), (4,), (5,)) or counters.dtype.kind not in "iu":
        raise ValueError(f"state['counters'] has {counters.dtype} {counters.shape}, "
                         "expected 3 to 5 integers")
    if (counters > MAX_STATE_COUNTER).any():
        raise ValueError(f"state counters beyond 2**62: {counters.tolist()}")
    full = np.array([-1, -1, -1, -1, 0], dtype=np.int64)
    full[: counters.size] = counters
    if full[K.I_FORGOTTEN] < 0:
        raise ValueError(f"state counters are invalid: {full.tolist()}")
    return full


def _node_ids(state: dict[str, np.ndarray], n: int, next_id: int) -> tuple[np.ndarray, int]:
    """The persistent node ids and the next free id; a state saved before ids existed gets
    fresh ids 0..n-1 (identities do not survive such a restore, positions and edges do)."""
    if "ids" not in state:
        return np.arange(n, dtype=np.int64), max(n, next_id)
    ids = _array(state, "ids", (n,), "iu").astype(np.int64)
    if (ids < 0).any() or np.unique(ids).size != n:
        raise ValueError("state['ids'] must be distinct non-negative node ids")
    if next_id < 0:
        next_id = int(ids.max()) + 1
    if next_id <= ids.max():
        raise ValueError(f"state next id {next_id} is not above every node id ({ids.max()})")
    return ids, next_id


def _check_adjacency(n: int, arrays: dict[str, np.ndarray]) -> None:
    """Every used slot names a valid neighbour whose twin slot points back with equal age/mask."""
    deg = arrays["deg"].astype(np.int64)
    if (deg < 1).any() or (deg > K.MAX_DEGREE).any():
        raise ValueError(f"state['deg'] must be in 1..{K.MAX_DEGREE} for every node")
    used = np.arange(K.MAX_DEGREE) < deg[:, None]
    rows = np.broadcast_to(np.arange(n)[:, None], used.shape)[used]
    slots = np.broadcast_to(np.arange(K.MAX_DEGREE), used.shape)[used]
    nbr = arrays["nbr"].astype(np.int64)[used]
    rev = arrays["rev"].astype(np.int64)[used]
    if (nbr < 0).any() or (nbr >= n).any() or (nbr == rows).any():
        raise ValueError("state['nbr'] holds an out-of-range or self neighbour")
    if (rev < 0).any() or (rev >= deg[nbr]).any():
        raise ValueError("state['rev'] points outside the neighbour's used slots")
    twin_nbr = arrays["nbr"][nbr, rev]
    twin_rev = arrays["rev"][nbr, rev]
    if (twin_nbr != rows).any() or (twin_rev != slots).any():
        raise ValueError("state adjacency is not symmetric (nbr/rev disagree)")
    age = arrays["age"]
    emask = arrays["emask"]
    if (age[used] < 0).any() or (age[used] != age[nbr, rev]).any():
        raise ValueError("state['age'] is negative or differs between an edge's two ends")
    masks = emask[used]
    if (masks != emask[nbr, rev]).any() or ((masks & K.POS_BIT) == 0).any():
        raise ValueError("state['emask'] differs between an edge's ends or lacks the position bit")
    if (masks & ~np.uint8(K.POS_BIT | K.COL_BIT | K.NOR_BIT)).any():
        raise ValueError("state['emask'] has unknown property bits")
