"""Validation of the learners' hyper-parameters, in one place."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

#: node budget ceiling: the adjacency alone takes ~200 bytes a node, so 10 million nodes is
#: ~2 GB; a larger budget (e.g. from a crafted checkpoint) is refused before any allocation
MAX_NODES_LIMIT = 10_000_000


def check_integer(name: str, value: Any, minimum: int, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value}")
    return int(value)


def check_real(name: str, value: Any, low: float, high: float = math.inf,
          low_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if number < low or (low_open and number == low) or number > high:
        left = "(" if low_open else "["
        raise ValueError(f"{name} must be in {left}{low}, {high}], got {value!r}")
    return number


def validate_parameters(params: dict[str, Any]) -> dict[str, Any]:
    """Check every known hyper-parameter present in ``params``; return them normalised.

    Raises ValueError naming the offending parameter.
    """
    checked = dict(params)
    checked["max_nodes"] = check_integer("max_nodes", params["max_nodes"], 2, MAX_NODES_LIMIT)
    checked["lambda_"] = check_integer("lambda_", params["lambda_"], 1)
    checked["age_max"] = check_integer("age_max", params["age_max"], 1)
    checked["eta1"] = check_real("eta1", params["eta1"], 0.0, 1.0, low_open=True)
    checked["eta2"] = check_real("eta2", params["eta2"], 0.0, 1.0)
    if checked["eta2"] > checked["eta1"]:
        raise ValueError(f"eta2 ({checked['eta2']}) must not exceed eta1 ({checked['eta1']})")
    checked["alpha"] = check_real("alpha", params["alpha"], 0.0, 1.0)
    checked["beta"] = check_real("beta", params["beta"], 0.0, 1.0, low_open=False)
    if checked["beta"] >= 1.0:
        raise ValueError(f"beta must be < 1, got {checked['beta']}")
    if "tau_col" in params:
        checked["tau_col"] = check_real("tau_col", params["tau_col"], 0.0, low_open=True)
    if "tau_nor" in params:
        checked["tau_nor"] = check_real("tau_nor", params["tau_nor"], 0.0, low_open=True)
    if params.get("normal_angle_deg") is not None:
        checked["normal_angle_deg"] = check_real("normal_angle_deg", params["normal_angle_deg"],
                                                 0.0, 90.0, low_open=True)
    if params.get("normal_refresh_steps") is not None:
        checked["normal_refresh_steps"] = check_integer("normal_refresh_steps",
                                                        params["normal_refresh_steps"], 1)
    if "normal_mu" in params and params["normal_mu"] is not None:
        checked["normal_mu"] = check_real("normal_mu", params["normal_mu"], 0.0, low_open=True)
    if "viewpoint" in params and params["viewpoint"] is not None:
        try:
            viewpoint = np.asarray(params["viewpoint"], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"viewpoint must be 3 numbers or None: {exc}") from exc
        if viewpoint.shape != (3,) or not np.isfinite(viewpoint).all():
            raise ValueError(
                f"viewpoint must be 3 finite numbers or None, got {params['viewpoint']!r}"
            )
        checked["viewpoint"] = tuple(float(v) for v in viewpoint)
    if params.get("utility_k") is not None:
        # 0 turns forgetting off, like None: params files (TOML) have no None
        checked["utility_k"] = (check_real("utility_k", params["utility_k"], 0.0) or None)
    if "utility_decay" in params:
        checked["utility_decay"] = check_real("utility_decay", params["utility_decay"], 0.0, 1.0)
        if checked["utility_decay"] >= 1.0:
            raise ValueError(f"utility_decay must be < 1, got {checked['utility_decay']}")
    if "view_depth_margin" in params:
        checked["view_depth_margin"] = check_real(
            "view_depth_margin", params["view_depth_margin"], 0.0, 10.0
        )
    if "replay_share" in params:
        checked["replay_share"] = check_real("replay_share", params["replay_share"], 0.0, 1.0)
        if checked["replay_share"] >= 1.0:
            raise ValueError(f"replay_share must be < 1, got {checked['replay_share']}")
    if "replay_points" in params:
        checked["replay_points"] = check_integer("replay_points", params["replay_points"], 1,
                                                 MAX_NODES_LIMIT)
    for weight in ("w_pos", "w_col"):
        if weight in params:
            checked[weight] = check_real(weight, params[weight], 0.0)
    if "w_pos" in params and checked["w_pos"] == 0.0:
        raise ValueError("w_pos must be > 0 (the position drives the topology)")
    random_state = params.get("random_state")
    if random_state is not None:
        checked["random_state"] = check_integer("random_state", random_state, 0)
    return checked
