"""The paper's baselines GNG and GNG-W: one topology, winner by position and colour together.

They share the learning loop and everything else with `GNGDT` (`gngdt.core.gas.model.GrowingGas`):

- `GNG`: Euclidean distance over the concatenated vector (position, colour).
- `GNGW`: weighted distance ``w_pos ||dpos|| + w_col ||dcol||`` (eq. 13) and error
  ``w_pos ||dpos||^2 + w_col ||dcol||^2`` (eq. 14).
"""

from __future__ import annotations

from gngdt.core.gas.model import GrowingGas
from gngdt.core.kernels import layout as K


class GNG(GrowingGas):
    """Plain GNG on the concatenated (position, colour) vector; one topology ("pos")."""

    _MODE = K.MODE_GNG

    def __init__(self, max_nodes: int = 1000, lambda_: int = 500, eta1: float = 0.025,
                 eta2: float = 0.0003, age_max: int = 88, alpha: float = 0.5,
                 beta: float = 0.0005, random_state: int | None = None) -> None:
        super().__init__(max_nodes=max_nodes, lambda_=lambda_, eta1=eta1, eta2=eta2,
                         age_max=age_max, alpha=alpha, beta=beta, random_state=random_state)


class GNGW(GrowingGas):
    """GNG with the weighted distance of eqs. 13-14 (paper defaults w_pos=0.8, w_col=0.2)."""

    _MODE = K.MODE_GNGW
    _PARAM_NAMES = (*GrowingGas._PARAM_NAMES, "w_pos", "w_col")

    def __init__(self, max_nodes: int = 1000, lambda_: int = 500, eta1: float = 0.025,
                 eta2: float = 0.0003, age_max: int = 88, alpha: float = 0.5,
                 beta: float = 0.0005, w_pos: float = 0.8, w_col: float = 0.2,
                 random_state: int | None = None) -> None:
        super().__init__(max_nodes=max_nodes, lambda_=lambda_, eta1=eta1, eta2=eta2,
                         age_max=age_max, alpha=alpha, beta=beta, w_pos=w_pos, w_col=w_col,
                         random_state=random_state)
