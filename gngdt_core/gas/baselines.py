"""The paper's baselines GNG and GNG-W: one topology, winner by position and colour together.

They share the learning loop and everything else with `GNGDT` (`gngdt.core.gas.model.GrowingGas`):

- `GNG`: Euclidean distance over the concatenated vector (position, colour).
- `GNGW`: weighted distance ``w_pos ||dpos|| + w_col ||dcol||`` (eq. 13) and error
  ``w_pos ||dpos||^2 + w_col ||dcol||^2`` (eq. 14).
"""

from __future__ import annotations

from gngdt.core.gas.model import GrowingGas
from gngdt.core.kernels import layout as K
from gngdt.core.parameters import Interval, estimator, param


@estimator
class GNG(GrowingGas):
    """Plain GNG on the concatenated (position, colour) vector; one topology ("pos")."""

    _MODE = K.MODE_GNG


@estimator
class GNGW(GrowingGas):
    """GNG with the weighted distance of eqs. 13-14 (paper defaults w_pos=0.8, w_col=0.2)."""

    _MODE = K.MODE_GNGW

    w_pos: float = param(0.8, Interval(float, 0.0, closed="neither"),
                         "weight of the position distance (eqs. 13-14)")
    w_col: float = param(0.2, Interval(float, 0.0), "weight of the colour distance (eqs. 13-14)")
