"""scikit-learn style online estimator GNG-DT, and the machinery it shares with the paper's
baselines GNG and GNG-W (`gngdt.core.gas.baselines`).

All three share one numba learning loop (`kernels.learning.learn`); they differ in the winner
distance and in which topologies they keep. `GNGDT`: winner and error by position only (eqs.
2-3); one topology per property: "pos", "col" (when colours are learned) and "nor" (3-D
positions). Normals (eq. 16) are oriented toward ``viewpoint`` (the sensor origin by default;
``None`` leaves the sign as computed) and compared sign-invariantly in eqs. 4 and 9
(``min(||n_i - n_j||, ||n_i + n_j||) < tau_nor``), so the normal topology never depends on the
orientation. The baselines keep one topology and pick the winner by position and colour.

Step 0 places the two initial nodes on two random input samples. Growth stops at ``max_nodes``
(Step 8 is then skipped entirely; with ``resolution_m``, at the surface seen); adaptation goes on.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Self

import numpy as np

from gngdt.core.clustering import COL, NOR, POS
from gngdt.core.gas.coverage import SurfaceCoverage
from gngdt.core.gas.queries import NetworkQueries
from gngdt.core.gas.rehearsal import SampleMemory
from gngdt.core.gas.sampling import (
    batch_rows,
    check_batch,
    check_n_steps,
    checked_pose,
    gather,
    initial_indices,
    sample_orders,
    to_model_frame,
)
from gngdt.core.gas.state import restore, snapshot
from gngdt.core.kernels import layout as K
from gngdt.core.kernels import segmentation as SK
from gngdt.core.kernels.graph import add_edge
from gngdt.core.kernels.learning import learn
from gngdt.core.parameters import (
    MAX_NODES_LIMIT,
    Estimator,
    Interval,
    Point3,
    estimator,
    param,
)
from gngdt.core.segmentation.network import Segmentation, SegmentationParams, segment_network
from gngdt.core.sensor.view import SensorView, rigid_inverse, see_batch


@estimator
class GrowingGas(NetworkQueries, Estimator):
    """Shared machinery and the parameters all three estimators have (the paper's Table 1 and a
    node budget); see `GNGDT` for the public API."""

    _MODE: ClassVar[int]
    #: parameters that shape the learner's state (its arrays' size, the random stream, the
    #: rehearsal memory, the surface seen): fixed from the ``fit`` that starts a network
    _STATE_PARAMS: ClassVar[tuple[str, ...]] = ("max_nodes", "random_state")

    max_nodes: int = param(1000, Interval(int, 2, MAX_NODES_LIMIT),
                           "node budget (with resolution_m: the memory cap)")
    lambda_: int = param(500, Interval(int, 1), "steps between node insertions (Step 8)")
    eta1: float = param(0.025, Interval(float, 0.0, 1.0, closed="right"),
                        "the winner's learning rate (Step 5)")
    eta2: float = param(0.0003, Interval(float, 0.0, 1.0),
                        "its neighbours' learning rate (Step 5), at most eta1")
    age_max: int = param(88, Interval(int, 1), "age at which an edge goes (Step 7)")
    alpha: float = param(0.5, Interval(float, 0.0, 1.0),
                         "error decrease of the two nodes an insertion splits (Step 8)")
    beta: float = param(0.0005, Interval(float, 0.0, 1.0, closed="left"),
                        "error decay per step (Step 9)")
    random_state: int | None = param(None, Interval(int, 0, optional=True),
                                     "seed of the first nodes and the sampling order")

    def __post_init__(self) -> None:
        """An unfitted learner: no network yet, parameters unchecked until ``fit``."""
        self._unfitted()

    def _unfitted(self) -> None:
        #: the checked parameters the current network learns with (None before ``fit``)
        self._params: dict[str, Any] | None = None
        self._rng: np.random.Generator | None = None
        self._dim = 0
        self._has_col = False
        self.n_invalid_ = 0
        #: the network (no nodes' room until the first batch fixes the dimension)
        self._network = K.Network.allocate(0, 2)
        #: the last batch's camera pose (None: the model's frame is the camera's)
        self._camera_pose: np.ndarray | None = None
        #: stored normals are eq. 16 of the current positions (refreshed after the last step)
        self._normals_fresh = False
        #: earlier batches' samples for rehearsal (``replay_share``; None: off)
        self._memory: SampleMemory | None = None
        #: the surface seen, at ``resolution_m`` (None: a fixed node budget)
        self._coverage: SurfaceCoverage | None = None

    def check_params(self) -> dict[str, Any]:
        """The parameters checked and normalised (`Estimator.check_params`; 0 turns
        ``utility_k`` and ``resolution_m`` off, as None: TOML has no None); ValueError naming
        the first that is not valid, or eta2 above eta1."""
        checked = super().check_params()
        for name in ("utility_k", "resolution_m"):
            if checked.get(name) == 0.0:
                checked[name] = None
        if checked["eta2"] > checked["eta1"]:
            raise ValueError(f"eta2 ({checked['eta2']}) must not exceed eta1 ({checked['eta1']})")
        return checked

    # ------------------------------------------------------------------ state

    def _start(self, params: dict[str, Any]) -> None:
        """A new, empty network learning with the checked ``params``."""
        self._unfitted()
        self._params = params
        self._rng = np.random.default_rng(params["random_state"])
        if params.get("replay_share"):
            self._memory = SampleMemory(params["replay_points"])
        if params.get("resolution_m"):
            self._coverage = SurfaceCoverage(params["resolution_m"])

    def _settled_params(self) -> dict[str, Any]:
        """The parameters checked for this batch: the first starts the network with them;
        later ones may change how it learns, not what its state holds (`_STATE_PARAMS`)."""
        params = self.check_params()
        if self._params is None:
            self._start(params)
            return params
        for name in self._STATE_PARAMS:
            if params[name] != self._params[name]:
                raise ValueError(f"{name} is {self._params[name]!r} in the network learned so "
                                 f"far, not {params[name]!r}: fit learns a new network with it")
        self._params = params
        return params

    @property
    def _settings(self) -> dict[str, Any]:
        """The parameters the network learns with (checked now, before the first batch)."""
        return self.check_params() if self._params is None else self._params

    def _allocate(self, dim: int, has_col: bool) -> None:
        self._dim = dim
        self._has_col = has_col
        self._network = K.Network.allocate(self._params["max_nodes"], dim, self._istate,
                                           self._fstate)

    @property
    def _istate(self) -> np.ndarray:
        """(5,) int64 counters (`kernels.layout.Network.istate`)."""
        return self._network.istate

    @property
    def _fstate(self) -> np.ndarray:
        """(4,) float64 lazy scales and grid state (`kernels.layout.Network.fstate`)."""
        return self._network.fstate

    @property
    def _arrays(self) -> dict[str, np.ndarray]:
        """The network's arrays by field name (`kernels.layout.Network`)."""
        return self._network._asdict()

    @property
    def _forgets(self) -> bool:
        return self._settings.get("utility_k") is not None

    def _kernel_parameters(self, camera_pose: np.ndarray | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
        """Kernel parameters; ``camera_pose`` places the viewpoint (default: the last batch's)."""
        p = self._params
        viewpoint = p.get("viewpoint")
        camera_pose = self._camera_pose if camera_pose is None else camera_pose
        if viewpoint is not None and camera_pose is not None:  # the sensor's place in this batch
            viewpoint = camera_pose[:3, :3] @ np.asarray(viewpoint) + camera_pose[:3, 3]
        tau_nor = p.get("tau_nor", 1.0)
        if p.get("normal_angle_deg") is not None:  # the chord between unit vectors that far apart
            tau_nor = 2.0 * math.sin(math.radians(p["normal_angle_deg"]) / 2.0)
        fparams = np.array([
            p["eta1"], p["eta2"], p["alpha"], p["beta"],
            p.get("tau_col", 1.0), tau_nor, p.get("normal_mu") or 0.0,
            *(viewpoint if viewpoint is not None else (0.0, 0.0, 0.0)),
            p.get("w_pos", 1.0), p.get("w_col", 1.0), p.get("utility_k") or 0.0,
            p.get("utility_decay", 0.0), p.get("resolution_m") or 0.0,
        ])
        has_nor = self._MODE == K.MODE_GNGDT and self._dim == 3
        iparams = np.array([
            p["lambda_"], p["age_max"], self.growth_limit_, self._MODE,
            int(self._has_col), int(has_nor), int(viewpoint is not None), int(self._forgets),
            np.iinfo(np.int64).max,  # Q_FRAME_ROWS: every sample is the batch's (no rehearsal)
        ], dtype=np.int64)
        return fparams, iparams

    # ------------------------------------------------------------------ learning

    def fit(self, positions: Any, colors: Any = None, n_steps: int | None = None,
            camera_pose: Any = None) -> Self:
        """Forget everything (the RNG is re-seeded from ``random_state``), then learn with the
        parameters as they are now; ValueError naming a parameter that is not valid."""
        self._start(self.check_params())
        return self.partial_fit(positions, colors, n_steps, camera_pose)

    def partial_fit(self, positions: Any, colors: Any = None, n_steps: int | None = None,
                    camera_pose: Any = None) -> Self:
        """Learn ``n_steps`` samples (default: one pass) drawn in random order from the batch.

        positions: (N, D) numeric, D = 2 or 3 (same D on every call); colors: (N, 3) numeric, any
        scale, or None (given on every call or on none). Rows with NaN/inf are dropped and counted
        in ``n_invalid_``.

        camera_pose: (4, 4) camera-to-world transform of this batch (3-D only), or None. With it,
        ``positions`` are in the camera frame (x right, y down, z forward) and are learned in the
        fixed frame the pose maps them into, so the network is a map in that frame; normals face
        the camera's place in this batch (``viewpoint`` is then given in the camera frame). Without
        it the model's frame is the batch's own. See `GNGDT` for forgetting, which judges nodes
        against this batch seen from this pose.

        The parameters are checked first (ValueError naming one that is not valid); the first
        batch starts a network with them, and a later one refuses a change of those that shape
        its state (``max_nodes``, ``random_state``, the rehearsal memory's, ``resolution_m``:
        `fit` starts a new network with them).
        """
        self._settled_params()
        batch, batch_colors, finite_rows, n_invalid = check_batch(positions, colors)
        # rehearsal needs a fixed frame: without a pose, what was seen before is elsewhere now
        memory = self._memory if camera_pose is not None else None
        camera_pose = checked_pose(camera_pose, batch.shape[1])
        check_n_steps(n_steps)
        has_col = batch_colors is not None
        if self._dim == 0:
            self._allocate(batch.shape[1], has_col)
        else:
            self._check_consistent(batch.shape[1], has_col)
        self.n_invalid_ += n_invalid
        n_samples = batch.shape[0] if finite_rows is None else finite_rows.size
        if n_samples == 0:
            return self
        if self._coverage is not None:  # before Step 0: the first batch's budget counts
            self._coverage.add(batch, camera_pose)
        steps = n_samples if n_steps is None else int(n_steps)
        replay_steps = self._replay_steps(steps, memory)
        steps -= replay_steps  # the batch's own
        if self.n_nodes_ == 0:
            first_two = batch_rows(finite_rows, initial_indices(self._rng, n_samples))
            initial, initial_colors = gather(batch, batch_colors, first_two)
            self._initialise(to_model_frame(initial, camera_pose), initial_colors)
        self._camera_pose = camera_pose
        fparams, iparams = self._kernel_parameters()
        # Fewer steps than samples (a large frame): convert only the sampled rows, so a frame
        # costs what its steps cost. A pass or more: convert the batch once, visit it by index.
        whole_batch = None
        self._normals_fresh = False
        if steps >= n_samples:
            camera_samples, sample_colors = gather(batch, batch_colors, finite_rows)
            self._see(camera_samples, camera_pose, memory)
            whole_batch = to_model_frame(camera_samples, camera_pose), sample_colors
        learned = replayed = 0
        for chunk, order in enumerate(sample_orders(self._rng, n_samples, steps)):
            if whole_batch is None:
                samples, sample_colors = gather(batch, batch_colors, batch_rows(finite_rows, order))
                if chunk == 0:
                    self._see(samples, camera_pose, memory)
                samples = to_model_frame(samples, camera_pose)
                order = np.arange(order.size)
            else:
                samples, sample_colors = whole_batch
            batch_samples = (samples, sample_colors)
            learned += order.size
            if replay_steps:  # this chunk's share of the rehearsal, mixed into its order
                done, replayed = replayed, round(replay_steps * learned / steps)
                samples, sample_colors, order = self._with_rehearsal(
                    samples, sample_colors, order, replayed - done)
            iparams[K.Q_FRAME_ROWS] = len(batch_samples[0])
            self._learn(samples, sample_colors, order, fparams, iparams)
            if memory is not None and (whole_batch is None or chunk == 0):
                memory.offer(*batch_samples, self._rng)  # each learned sample once
        return self

    def _learn(self, samples: np.ndarray, sample_colors: np.ndarray | None, order: np.ndarray,
               fparams: np.ndarray, iparams: np.ndarray) -> None:
        """Steps 1-9 for the rows ``order`` of ``samples`` (model frame), with eq. 16 and eqs.
        4/9 refreshed every ``normal_refresh_steps`` steps when that is set."""
        kernel_colors = sample_colors if sample_colors is not None else np.zeros((1, 3))
        for part in self._refresh_parts(order):
            learn(samples, kernel_colors, part, self._network, fparams, iparams)
            if self._params.get("normal_refresh_steps"):
                self.refresh_normals()

    def _replay_steps(self, steps: int, memory: SampleMemory | None) -> int:
        """Steps of this batch drawn from ``memory`` (none without one, or before it holds
        anything), leaving at least one for the batch itself."""
        if memory is None or memory.count == 0 or steps < 2:
            return 0
        return min(round(self._params["replay_share"] * steps), steps - 1)

    def _with_rehearsal(self, samples: np.ndarray, sample_colors: np.ndarray | None,
                        order: np.ndarray, count: int
                        ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """The batch's samples (model frame) with ``count`` drawn from the memory appended, and
        ``order`` with their rows, shuffled in."""
        remembered, remembered_colors = self._memory.draw(self._rng, count)
        rows = np.arange(len(samples), len(samples) + count)
        samples = np.concatenate([samples, remembered])
        if sample_colors is not None:
            sample_colors = np.concatenate([sample_colors, remembered_colors])
        return samples, sample_colors, self._rng.permutation(np.concatenate([order, rows]))

    def _refresh_parts(self, order: np.ndarray) -> list[np.ndarray]:
        """``order`` cut into runs of ``normal_refresh_steps`` (whole when refresh is off)."""
        every = self._params.get("normal_refresh_steps")
        if not every:
            return [order]
        return [order[start:start + every] for start in range(0, order.size, every)]

    def refresh_normals(self) -> None:
        """Recompute eq. 16 for every node, then eqs. 4/9 for every edge, from the current nodes
        (``normal_refresh_steps`` does this periodically while learning)."""
        fparams, iparams = self._kernel_parameters()
        if iparams[K.Q_HAS_NOR]:
            self._refresh_normals(self._network, fparams, iparams)
        SK.refresh_property_bits(self._network, bool(iparams[K.Q_HAS_COL]),
                                 bool(iparams[K.Q_HAS_NOR]), fparams[K.P_TAU_COL],
                                 fparams[K.P_TAU_NOR])
        self._normals_fresh = bool(iparams[K.Q_HAS_NOR])

    @staticmethod
    def _refresh_normals(net: K.Network, fparams: np.ndarray, iparams: np.ndarray) -> None:
        """Eq. 16 for every node of ``net`` (its ``nor`` written) with the kernel parameters."""
        SK.refresh_normals(net, fparams[K.P_MU], bool(iparams[K.Q_ORIENT]), fparams[K.P_VX],
                           fparams[K.P_VY], fparams[K.P_VZ])

    def _see(self, camera_samples: np.ndarray, camera_pose: np.ndarray | None,
             memory: SampleMemory | None) -> None:
        """What this batch's sensor saw (`gngdt.core.sensor.view.see_batch`): the nodes forgetting
        judges, the samples of ``memory`` (rehearsal) it saw through."""
        if self._forgets or memory is not None:
            net = self._network
            see_batch(camera_samples, camera_pose, net.pos, self.n_nodes_,
                      net.judged if self._forgets else None, self._dim,
                      self._fstate[K.F_SPACING], self._params["view_depth_margin"], memory)

    def _check_consistent(self, dim: int, has_col: bool) -> None:
        if dim != self._dim:
            raise ValueError(f"positions have {dim} columns, the model learned {self._dim}-D data")
        if has_col != self._has_col:
            expected = "given" if self._has_col else "None"
            raise ValueError(f"colors must be {expected}, as in the first batch this model learned")

    def _initialise(self, samples: np.ndarray, sample_colors: np.ndarray | None) -> None:
        """Step 0: two nodes on two random samples (``samples`` (2, D)), connected in every
        property with age 0."""
        net = self._network
        for node in (0, 1):
            net.pos[node] = samples[node]
            if sample_colors is not None:
                net.col[node] = sample_colors[node]
        all_bits = K.POS_BIT | K.COL_BIT | K.NOR_BIT
        add_edge(net, 0, 1, all_bits)
        net.ids[:2] = self._istate[K.I_NEXT_ID] + np.arange(2)
        net.wins[:2] = 1.0
        self._istate[K.I_NEXT_ID] += 2
        self._istate[K.I_NODES] = 2

    # ------------------------------------------------------------------ fitted state

    @property
    def n_nodes_(self) -> int:
        return int(self._istate[K.I_NODES])

    @property
    def n_steps_(self) -> int:
        return int(self._istate[K.I_STEPS])

    @property
    def growth_limit_(self) -> int:
        """Nodes it may grow to now: ``max_nodes``, or one per cell seen (``resolution_m``)."""
        cap = self._settings["max_nodes"]
        return cap if self._coverage is None else min(cap, max(2, self._coverage.count))

    @property
    def properties_(self) -> tuple[str, ...]:
        return (POS,)

    @property
    def positions_(self) -> np.ndarray:
        """(n_nodes, D) float64 node positions, in the input's units (D = 2 before any)."""
        return self._network.pos[: self.n_nodes_].copy()

    @property
    def colors_(self) -> np.ndarray:
        """(n_nodes, 3) float64 node colours on the input's scale (zeros if none learned)."""
        return self._network.col[: self.n_nodes_].copy()

    @property
    def normals_(self) -> np.ndarray:
        """(n_nodes, 3) float64 unit normals; (0, 0, 0) where undefined or not learned."""
        return self._network.nor[: self.n_nodes_].copy()

    @property
    def node_ids_(self) -> np.ndarray:
        """(n_nodes,) int64 persistent node ids, row for row with the other node arrays.

        A node keeps its id for its whole life although its index changes (a deletion moves the
        last node into the hole); every new node gets an id never used before in this model.
        """
        return self._network.ids[: self.n_nodes_].copy()

    @property
    def errors_(self) -> np.ndarray:
        """(n_nodes,) float64 accumulated errors with all decay applied."""
        return self._network.err[: self.n_nodes_] * self._fstate[K.F_ERROR_SCALE]

    # ------------------------------------------------------------------ checkpoints

    def get_state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue exactly, as numpy arrays only (np.savez-safe)."""
        return snapshot(self)

    @classmethod
    def from_state(cls, state: dict[str, np.ndarray]) -> Self:
        """Rebuild a model saved by `get_state`; ValueError on anything inconsistent."""
        return restore(cls, state)


@estimator
class GNGDT(GrowingGas):
    """Growing Neural Gas with Different Topologies (Toda et al., Steps 0-10).

    Defaults are the paper's Table 1 plus a node budget. ``normal_mu=None`` (default) uses, per
    node, the mean distance to its position neighbours as the eq. 16 coefficient, so normals do not
    depend on the data's scale. ``viewpoint``: normals are flipped to face it (None: no orienting).

    Beyond the paper (off by default): ``normal_angle_deg`` states the normal threshold as what it
    means — a normal edge is kept while the (sign-invariant) angle between the two normals is
    below it; it replaces ``tau_nor`` (the chord ``2 sin(angle / 2)``). ``normal_refresh_steps``
    keeps normals fresh: the paper recomputes eq. 16 only for each step's winner, so a node's
    normal lags behind its neighbours' moves; with it, eq. 16 is recomputed for every node, and
    eqs. 4/9 for every edge, every that many steps and at the end of each `partial_fit`.

    Forgetting (off by default, as in the paper): with ``utility_k`` > 0, nodes that stop
    representing data are removed as in GNG-U (Fritzke 1997): each node's utility accumulates,
    for the samples it wins, the squared distance to the second winner minus that to the winner,
    and decays by ``utility_decay`` per step (GNG-U2's chi, Toda et al. 2016: slower than
    ``beta``, so that a node winning a sample every few thousand steps keeps its utility); every
    ``lambda_`` steps the node of least utility goes, with its edges, when
    ``max error > utility_k * its utility``. Only nodes the sensor
    could see in the current batch are judged (their utility decays, they may be removed): put in
    the camera frame, inside the batch's view and not behind its farthest measured depth by more
    than ``view_depth_margin`` times that depth (``gngdt.core.sensor.view``). The rest of the map
    keeps its utility, frozen, however long it is out of view. 3-D batches are then taken as a depth
    camera's points (camera frame, z forward; or mapped by ``camera_pose``); in 2-D every node is
    judged.

    Resolution (off by default: the paper's budget): with ``resolution_m`` the network grows with
    the world, one node per cubic cell of that size the batches' points fell in (in the model's
    frame; `gngdt.core.gas.coverage`) within ``max_nodes``, the memory cap.

    Rehearsal (off by default; 3-D batches with a ``camera_pose``, i.e. a map in a fixed frame:
    without a pose what was seen before is elsewhere now): with ``replay_share`` > 0, that share
    of each such `partial_fit`'s steps learns samples of earlier batches, not the batch's, drawn
    from a memory of ``replay_points`` samples (in the model's frame, colours with them): a
    uniform random sample of every batch sample learned so far, less those a later batch saw
    through (in front of the nearest depth measured there by more than ``view_depth_margin``
    times it; `gngdt.core.gas.rehearsal`). A moving camera shows one part of the world at a time;
    without rehearsal the nodes in view follow the current batch, and a part that leaves the
    view keeps its nodes as its last view placed them. With it the network learns the world
    seen so far, and what vanished or moved leaves the memory as soon as the sensor looks
    there. Rehearsed samples move nodes and add error, but not utility:
    forgetting judges nodes by what the sensor sees now.
    """

    _MODE = K.MODE_GNGDT
    _STATE_PARAMS = (*GrowingGas._STATE_PARAMS, "replay_share", "replay_points", "resolution_m")

    tau_col: float = param(10.0, Interval(float, 0.0, closed="neither"),
                           "colour distance below which an edge is a colour edge (eq. 4)")
    tau_nor: float = param(0.02, Interval(float, 0.0, closed="neither"),
                           "normal distance below which an edge is a normal edge (eq. 9)")
    normal_mu: float | None = param(None, Interval(float, 0.0, closed="neither", optional=True),
                                    "eq. 16's weight scale (None: mean neighbour distance)")
    viewpoint: tuple[float, float, float] | None = param(
        (0.0, 0.0, 0.0), Point3(optional=True),
        "the point normals face, in the camera frame (None: not oriented)")
    normal_angle_deg: float | None = param(
        None, Interval(float, 0.0, 90.0, closed="right", optional=True),
        "the normal threshold as an angle (replaces tau_nor)")
    normal_refresh_steps: int | None = param(None, Interval(int, 1, optional=True),
                                             "steps between refreshing every normal")
    # 0 turns forgetting off, like None (params files, TOML, have no None)
    utility_k: float | None = param(None, Interval(float, 0.0, optional=True),
                                    "forgetting (GNG-U): error to utility ratio that removes")
    utility_decay: float = param(1e-4, Interval(float, 0.0, 1.0, closed="left"),
                                 "utility decay per step of a node in view")
    view_depth_margin: float = param(0.05, Interval(float, 0.0, 10.0),
                                     "depth tolerance of 'in view', as a share of the depth")
    replay_share: float = param(0.0, Interval(float, 0.0, 1.0, closed="left"),
                                "share of a posed batch's steps learning remembered samples")
    replay_points: int = param(40_000, Interval(int, 1, MAX_NODES_LIMIT),
                               "samples the rehearsal memory holds")
    # metres: one node per cell of this size of the surface seen (None or 0: the fixed budget)
    resolution_m: float | None = param(None, Interval(float, 0.0, optional=True),
                                       "one node per cell of this size seen (metres)")

    @property
    def n_forgotten_(self) -> int:
        """Nodes removed so far by forgetting (and neighbours it left without an edge)."""
        return int(self._istate[K.I_FORGOTTEN])

    @property
    def judged_(self) -> np.ndarray:
        """(n_nodes,) bool: the nodes the last batch judged (forgetting on; else all False).
        Nodes inserted during the batch count as judged."""
        if not self._forgets:
            return np.zeros(self.n_nodes_, dtype=bool)
        return self._network.judged[: self.n_nodes_].astype(bool)

    @property
    def utilities_(self) -> np.ndarray:
        """(n_nodes,) float64 utilities with all decay applied (zeros when not forgetting)."""
        return self._network.util[: self.n_nodes_] * self._fstate[K.F_UTIL_SCALE]

    @property
    def properties_(self) -> tuple[str, ...]:
        props = [POS]
        if self._has_col:
            props.append(COL)
        if self._dim == 3:
            props.append(NOR)
        return tuple(props)

    def fresh_normals(self) -> np.ndarray:
        """(n_nodes, 3) eq. 16 normals of every node from the current positions (the stored
        ``normals_`` are recomputed only for each step's winner, so they lag behind the nodes'
        moves). Unit vectors facing ``viewpoint``; zero where undefined. The model is unchanged.
        """
        if self._dim != 3:
            raise ValueError("normals need 3-D positions")
        if self._normals_fresh:  # refreshed after the last step (``normal_refresh_steps``)
            return self.normals_
        normals = self._network.nor.copy()
        fparams, iparams = self._kernel_parameters()
        self._refresh_normals(self._network._replace(nor=normals), fparams, iparams)
        return normals[: self.n_nodes_]

    def segmentation(self, params: SegmentationParams | None = None,
                     view: SensorView | None = None,
                     camera_pose: np.ndarray | None = None) -> Segmentation:
        """Segments of the current network by local convexity (`gngdt.core.segmentation.network`),
        from fresh normals and the position topology; details (patches, convex edges) included.
        view: what the sensor measured in the frame just learned (`SensorView.of` its points in
        the camera frame), to bridge gaps of missing depth; camera_pose: (4, 4) camera-to-model
        of that frame (None: the model is in the camera frame)."""
        return segment_network(self.positions_, self.fresh_normals(), self.edges(POS), params,
                               view, None if camera_pose is None else rigid_inverse(camera_pose))

    def segment(self, params: SegmentationParams | None = None) -> np.ndarray:
        """(n_nodes,) int32 segment of each node, 0..k-1 by decreasing size, -1 for lone
        fragments: one segment per object, support surfaces apart (see
        `gngdt.core.segmentation.network`). Label points with
        ``labels[model.predict(points)]``, an organized frame's pixels with `label_pixels`."""
        return self.segmentation(params).labels
