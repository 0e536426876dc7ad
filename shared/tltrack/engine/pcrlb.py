"""Posterior Cramér-Rao lower bound on the position error (Tichavsky, Muravchik & Nehorai 1998).

With additive Gaussian noise the information recursion is

    J_0 = P0^-1,   J_{k+1} = (Q_v + F_k J_k^-1 F_k')^-1 + sum_sensors H_{k+1}' R^-1 H_{k+1},

with F_k the Jacobian of f at the true x_k and H_{k+1} that of h at the true x_{k+1}. This form
needs no Q_v^-1, which does not exist (docs/background.md, "parameter traps"). Along one true
trajectory it is exact; for random truths the bound is averaged over the trajectories.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tltrack.models.base import MeasurementModel, MotionModel

Array = NDArray[np.float64]


def pcrlb(
    model: MotionModel,
    sensors_and_R: Sequence[tuple[MeasurementModel, Array]],
    truths: Array,
    P0: Array,
) -> Array:
    """Position bound sqrt(mean_trajectories([J^-1]_xx + [J^-1]_yy)) for k = 1..K, shape (K,).

    ``truths`` is (M, K + 1, n_x): M true trajectories x_0..x_K.
    """
    M, K1, n = truths.shape
    ix, iy = model.layout.pos
    Rinv = [np.linalg.inv(R) for _, R in sensors_and_R]
    Jinv = np.broadcast_to(np.asarray(P0, dtype=float), (M, n, n))  # J_0^-1 = P0
    bound = np.empty(K1 - 1)
    for k in range(1, K1):
        F = np.stack([model.F(x) for x in truths[:, k - 1]])
        J = np.linalg.inv(model.Q + F @ Jinv @ F.swapaxes(-1, -2))
        for (sensor, _), Ri in zip(sensors_and_R, Rinv, strict=True):
            H = np.stack([sensor.H(x) for x in truths[:, k]])
            J = J + H.swapaxes(-1, -2) @ Ri @ H
        Jinv = np.linalg.inv(J)
        bound[k - 1] = np.sqrt(np.mean(Jinv[:, ix, ix] + Jinv[:, iy, iy]))
    return bound
