"""A readable, slow GNG-DT: NumPy work per step, Steps 0-10 written out as in the paper.

It follows the same rules and tie-breaking as the numba kernel, so on the same samples in the same
order both produce the same network up to floating-point rounding:

- each node keeps its neighbours in the kernel's slot order (a new edge is appended; a removed
  edge's slot is taken by the node's last one), which decides the order in which Step 7 deletes
  nodes and which neighbour wins a tie in Step 8;
- a node has at most ``MAX_DEGREE`` edges: Step 4 creates no edge when either winner is full;
- nodes are deleted by moving the last node into the hole;
- normal edges are sign-invariant, normals are oriented toward the viewpoint, new nodes' normals
  are interpolated from their parents'.

Normals use ``numpy.linalg.eigh`` where the kernel has a closed form; in near-degenerate
neighbourhoods the two differ by up to ~1e-3. Used to check the fast kernel and as the naive
baseline of `benchmarks/bench_core.py`. Not meant for real work.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from gngdt.core.clustering import COL, NOR, POS
from gngdt.core.gas.model import GNGDT
from gngdt.core.gas.sampling import as_samples, initial_indices, sample_orders
from gngdt.core.kernels.layout import COL_BIT, I_NEXT_ID, MAX_DEGREE, NOR_BIT


@dataclass
class Edge:
    age: int
    properties: set[str] = field(default_factory=lambda: {POS})


def _key(i: int, j: int) -> tuple[int, int]:
    return (i, j) if i < j else (j, i)


class ReferenceGNGDT:
    """Per-step NumPy GNG-DT with the parameters of `GNGDT` (same names and defaults).

    ``events`` counts what the kernel handles specially: ``"deleted_nodes"`` (Step 7) and
    ``"degree_cap"`` (Step 4 found a winner with ``MAX_DEGREE`` edges and created no edge).
    """

    def __init__(self, **params: object) -> None:
        self.params = GNGDT(**params).check_params()  # the same validation and defaults
        self.rng = np.random.default_rng(self.params["random_state"])
        self.positions = np.zeros((0, 0))
        self.colors = np.zeros((0, 3))
        self.normals = np.zeros((0, 3))
        self.errors = np.zeros(0)
        self.ids = np.zeros(0, dtype=np.int64)  # persistent node ids; never reused
        self.next_id = 0
        self.edges: dict[tuple[int, int], Edge] = {}
        self.adjacency: list[list[int]] = []  # neighbours of each node, in slot order
        self.n_steps = 0
        self.has_col = False
        self.events: Counter[str] = Counter()

    @classmethod
    def from_model(cls, model: GNGDT) -> ReferenceGNGDT:
        """A reference learner continuing from a fitted `GNGDT`'s nodes and edges."""
        ref = cls(**model.get_params())
        ref.positions = model.positions_
        ref.colors = model.colors_
        ref.normals = model.normals_
        ref.errors = model.errors_
        ref.ids = model.node_ids_
        ref.next_id = int(model._istate[I_NEXT_ID])
        ref.has_col = COL in model.properties_
        ref.n_steps = model.n_steps_
        net = model._network
        for i in range(model.n_nodes_):
            ref.adjacency.append([int(j) for j in net.nbr[i, : net.deg[i]]])
            for k, j in enumerate(ref.adjacency[i]):
                if i < j:
                    bits = int(net.emask[i, k])
                    props = {POS} | {name for name, bit in ((COL, COL_BIT), (NOR, NOR_BIT))
                                       if bits & bit and name in model.properties_}
                    ref.edges[(i, j)] = Edge(int(net.age[i, k]), props)
        return ref

    # ------------------------------------------------------------------ helpers

    def neighbours(self, i: int) -> list[tuple[int, Edge]]:
        return [(j, self.edges[_key(i, j)]) for j in self.adjacency[i]]

    def _connect(self, i: int, j: int, properties: set[str]) -> bool:
        """A new edge of age 0; False (nothing changes) when ``i`` or ``j`` is full."""
        if max(len(self.adjacency[i]), len(self.adjacency[j])) >= MAX_DEGREE:
            return False
        self.adjacency[i].append(j)
        self.adjacency[j].append(i)
        self.edges[_key(i, j)] = Edge(0, properties)
        return True

    def _disconnect(self, i: int, j: int) -> None:
        del self.edges[_key(i, j)]
        for a, b in ((i, j), (j, i)):
            row = self.adjacency[a]
            row[row.index(b)] = row[-1]  # the last slot fills the hole
            row.pop()

    def _edge_properties(self, i: int, j: int) -> set[str]:
        """Eqs. 4 and 9: the position edge plus every property whose values are within tau."""
        props = {POS}
        if self.has_col and np.linalg.norm(self.colors[i] - self.colors[j]) < self.params[
            "tau_col"
        ]:
            props.add(COL)
        if self.positions.shape[1] == 3:
            ni, nj = self.normals[i], self.normals[j]
            if ni.any() and nj.any():
                distance = min(np.linalg.norm(ni - nj), np.linalg.norm(ni + nj))
                if distance < self.params["tau_nor"]:
                    props.add(NOR)
        return props

    def _orient(self, i: int) -> None:
        viewpoint = self.params["viewpoint"]
        if viewpoint is not None and self.normals[i] @ (viewpoint - self.positions[i]) < 0:
            self.normals[i] = -self.normals[i]

    def _normal(self, i: int) -> None:
        """Eq. 16 with eigh; zero when the smallest eigenvector is not unique."""
        neighbours = self.adjacency[i]
        self.normals[i] = 0.0
        if len(neighbours) < 2:
            return
        h_i = self.positions[i]
        h_j = self.positions[neighbours]
        distances = np.linalg.norm(h_j - h_i, axis=1)
        mu = self.params["normal_mu"] or distances.mean()
        weights = np.exp(-(distances**2) / mu**2)
        centre = (h_i + weights @ h_j) / (1.0 + weights.sum())
        deviations = h_j - centre
        covariance = deviations.T @ deviations
        eigenvalues, eigenvectors = np.linalg.eigh(covariance)
        spread = np.sum((eigenvalues - eigenvalues.mean()) ** 2)
        gap = (eigenvalues[1] - eigenvalues[0]) * (eigenvalues[2] - eigenvalues[0])
        if spread <= 0 or gap <= 1e-10 * spread:
            return
        self.normals[i] = eigenvectors[:, 0]
        self._orient(i)

    def _delete_node(self, i: int) -> int:
        """Remove isolated node ``i``; the last node takes index ``i``. Returns the old last."""
        self.events["deleted_nodes"] += 1
        last = len(self.errors) - 1
        for array_name in ("positions", "colors", "normals", "errors", "ids"):
            array = getattr(self, array_name)
            array[i] = array[last]
            setattr(self, array_name, array[:last])
        moved = self.adjacency.pop()
        if i != last:
            self.adjacency[i] = moved
            for j in moved:  # the neighbours keep their slot, now pointing at i
                row = self.adjacency[j]
                row[row.index(last)] = i
                self.edges[_key(i, j)] = self.edges.pop(_key(last, j))
        return last

    # ------------------------------------------------------------------ learning

    def partial_fit(self, positions: np.ndarray, colors: np.ndarray | None = None,
                    n_steps: int | None = None) -> ReferenceGNGDT:
        samples, sample_colors, _ = as_samples(positions, colors)
        steps = samples.shape[0] if n_steps is None else n_steps
        if len(self.errors) == 0:  # Step 0
            self.has_col = sample_colors is not None
            first, second = initial_indices(self.rng, samples.shape[0])
            self.positions = samples[[first, second]].copy()
            self.colors = (sample_colors[[first, second]].copy() if self.has_col
                           else np.zeros((2, 3)))
            self.normals = np.zeros((2, 3))
            self.errors = np.zeros(2)
            self.adjacency = [[1], [0]]
            self.ids = np.array([0, 1], dtype=np.int64)
            self.next_id = 2
            self.edges = {(0, 1): Edge(0, {POS, COL, NOR})}
        for order in sample_orders(self.rng, samples.shape[0], steps):
            for index in order:  # Step 1
                colour = sample_colors[index] if self.has_col else None
                self.step(samples[index], colour)
        return self

    def step(self, x: np.ndarray, colour: np.ndarray | None) -> None:
        """Steps 2-9 for one input."""
        p = self.params
        self.n_steps += 1
        # Step 2
        squared = np.sum((self.positions - x) ** 2, axis=1)
        s1, s2 = (int(k) for k in np.argsort(squared, kind="stable")[:2])
        # Step 3
        self.errors[s1] += squared[s1]
        # Step 4
        key = _key(s1, s2)
        if key in self.edges or self._connect(s1, s2, {POS}):
            self.edges[key].age = 0
            self.edges[key].properties = self._edge_properties(s1, s2)
        else:
            self.events["degree_cap"] += 1
        # Step 5
        self.positions[s1] += p["eta1"] * (x - self.positions[s1])
        if self.has_col:
            self.colors[s1] += p["eta1"] * (colour - self.colors[s1])
        for j, edge in self.neighbours(s1):
            self.positions[j] += p["eta2"] * (x - self.positions[j])
            if self.has_col and COL in edge.properties:
                self.colors[j] += p["eta2"] * (colour - self.colors[j])
            edge.age += 1  # Step 6
        # Step 7: expired edges of s1 in slot order (a removed slot is refilled: look again)
        candidates = []
        k = 0
        while k < len(self.adjacency[s1]):
            j = self.adjacency[s1][k]
            if self.edges[_key(s1, j)].age > p["age_max"]:
                candidates.append(j)
                self._disconnect(s1, j)
            else:
                k += 1
        for q, j in enumerate(candidates):
            if not self.adjacency[j]:
                last = self._delete_node(j)
                s1 = j if s1 == last else s1
                candidates[q + 1:] = [j if c == last else c for c in candidates[q + 1:]]
        if not self.adjacency[s1]:
            self._delete_node(s1)
        elif self.positions.shape[1] == 3:
            self._normal(s1)
        # Step 8
        if self.n_steps % p["lambda_"] == 0 and len(self.errors) < p["max_nodes"]:
            self._insert()
        # Step 9
        self.errors *= 1.0 - p["beta"]

    def _insert(self) -> None:
        alpha = self.params["alpha"]
        u = int(np.argmax(self.errors))
        f = max(self.adjacency[u], key=lambda j: self.errors[j])  # first in slot order on ties
        r = len(self.errors)
        self.positions = np.vstack([self.positions, 0.5 * (self.positions[u] + self.positions[f])])
        self.colors = np.vstack([self.colors, 0.5 * (self.colors[u] + self.colors[f])])
        sign = -1.0 if self.normals[u] @ self.normals[f] < 0 else 1.0
        normal = self.normals[u] + sign * self.normals[f]
        norm = np.linalg.norm(normal)
        self.normals = np.vstack([self.normals, normal / norm if norm**2 > 1e-24 else 0 * normal])
        if norm**2 > 1e-24:
            self._orient(r)
        self.adjacency.append([])
        self._disconnect(u, f)
        self._connect(u, r, self._edge_properties(u, r))
        self._connect(r, f, self._edge_properties(r, f))
        self.errors[u] -= alpha * self.errors[u]
        self.errors[f] -= alpha * self.errors[f]
        self.errors = np.append(self.errors, 0.5 * (self.errors[u] + self.errors[f]))
        self.ids = np.append(self.ids, self.next_id)
        self.next_id += 1
