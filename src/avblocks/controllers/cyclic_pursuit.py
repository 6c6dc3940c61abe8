r"""Cyclic pursuit: agent i chases agent i+1 (mod N), rotated by an angle.

Equations
---------
.. math::  u_i = K R(\phi) (x_{i+1} - x_i),\qquad
           R(\phi) = \begin{bmatrix}\cos\phi & -\sin\phi\\ \sin\phi & \cos\phi\end{bmatrix}

With ``phi = 0`` the agents rendezvous at their centroid (invariant). The
eigenvalues of the linear system are ``K (e^{i phi} w^k - 1)``, ``w =
e^{2 pi i / N}``; with ``phi = pi / N`` the slowest mode is marginally stable
and the agents converge to a regular N-gon turning about the centroid
(``phi > pi / N``: spirals out, ``phi < pi / N``: in). The ``order``
parameter sets who pursues whom (a permutation of the agents).

Reference: J. A. Marshall, M. E. Broucke & B. A. Francis, "Formations of
vehicles in cyclic pursuit", IEEE TAC 49(11), 2004.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar


def cyclic_pursuit_law(position, target_index, gain=1.0, angle=0.0, xp=np):
    """``K R(angle) (x[target] - x)`` for (N, 2) positions."""
    e = position[target_index] - position
    c, s = xp.cos(angle), xp.sin(angle)
    return gain * xp.stack([c * e[:, 0] - s * e[:, 1], s * e[:, 0] + c * e[:, 1]], axis=-1)


class CyclicPursuit(Block):
    """Cyclic pursuit for N single integrators in the plane.

    Ports: position (N, 2) in; velocity (N, 2) out.

    Parameters
    ----------
    n : int;  gain : float > 0;  angle : float (rad), ``pi / n`` for a circle.
    order : (N,) permutation, optional — ``order[k]`` pursues ``order[k+1]``.

    Numeric parameters
    ------------------

    ``gain`` and ``angle`` are numeric parameters; ``order`` is structural.
    """

    def __init__(self, n, *, gain=1.0, angle=0.0, order=None):
        super().__init__()
        self.n = n = int(n)
        self.declare_parameter("gain", positive_scalar(gain, "CyclicPursuit", "gain"),
                               bounds=(1e-12, None), unit="1/s")
        self.declare_parameter("angle", angle, shape=(), unit="rad")
        order = np.arange(n) if order is None else np.asarray(order)
        if sorted(order.tolist()) != list(range(n)):
            raise ParameterError("order must be a permutation of 0..n-1",
                                 block="CyclicPursuit", param="order")
        target = np.empty(n, dtype=np.int64)
        target[order] = np.roll(order, -1)
        self.target = target
        self.declare_input("position", (n, 2), unit="m")
        self.declare_output("velocity", (n, 2), unit="m/s")

    def output(self, t, x, u, xp):
        return {"velocity": cyclic_pursuit_law(u["position"], self.target, self.gain,
                                               self.angle, xp)}
