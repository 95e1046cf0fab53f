"""The paper's three methods as its experiments run them: GNG, GNG-W and GNG-DT with Table 1's
parameters, learned from scratch under a stopping rule, one sampling seed per trial.

Shared by the simulation (`paper`), the real frames (`paper_rgbd`) and `recording_eval`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gngdt.core.clustering import COL, NOR, POS
from gngdt.eval.paper_common import GNGDT_THRESHOLDS, GNGW_WEIGHTS, METHODS, PAPER_PARAMETERS


def trial_seed(trial: int) -> int:
    """Sampling seed of trial ``trial``: the same for every method, scale, noise level, frame."""
    return 1000 * trial + 1


def learn(model: Any, positions: np.ndarray, colors: np.ndarray | None, stop: str,
          steps: int) -> None:
    """Fit ``model`` from scratch under the stopping rule ``stop`` (see `PaperSettings`).

    "budget": the fewest steps that can grow ``model.max_nodes`` nodes (one per lambda steps),
    then lambda steps at a time while deletions keep the network below the budget, at most twice
    the growth in all. "steps": exactly ``steps`` steps.
    """
    if stop == "steps":
        model.fit(positions, colors, n_steps=steps)
        return
    lam, budget = model.lambda_, model.max_nodes
    growth = lam * (budget - 2)
    model.fit(positions, colors, n_steps=growth)
    while model.n_nodes_ < budget and model.n_steps_ < 2 * growth:
        missing = lam * (budget - model.n_nodes_) - model.n_steps_ % lam
        model.partial_fit(positions, colors, n_steps=min(missing, 2 * growth - model.n_steps_))


def make_model(method: str, max_nodes: int, random_state: int, **gngdt_extra: Any):
    """A fresh estimator for ``method`` with the paper's Table 1 parameters; ``gngdt_extra``:
    further GNG-DT arguments (forgetting), refused for the other methods."""
    from gngdt.core import GNG, GNGDT, GNGW

    if gngdt_extra and method != "GNG-DT":
        raise ValueError(f"{method} takes no {sorted(gngdt_extra)}")
    if method == "GNG-DT":
        return GNGDT(
            max_nodes=max_nodes, random_state=random_state, **PAPER_PARAMETERS, **GNGDT_THRESHOLDS,
            **gngdt_extra,
        )
    if method == "GNG-W":
        return GNGW(
            max_nodes=max_nodes, random_state=random_state, **PAPER_PARAMETERS, **GNGW_WEIGHTS
        )
    if method == "GNG":
        return GNG(max_nodes=max_nodes, random_state=random_state, **PAPER_PARAMETERS)
    raise ValueError(f"method: unknown {method!r} (choose from {METHODS})")


def clusterings_of(method: str, dimensions: int) -> tuple[tuple[str, ...], ...]:
    """The clusterings to count for a method: GNG-DT's topologies (normals only in 3D), else pos."""
    if method != "GNG-DT":
        return ((POS,),)
    if dimensions == 3:
        return ((POS,), (COL,), (NOR,), (COL, NOR))
    return ((POS,), (COL,))
