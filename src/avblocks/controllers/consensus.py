r"""Consensus (rendezvous) of single integrators on a communication graph.

Equations
---------
.. math::  \dot x_i = u_i = K \sum_{j \in N_i} a_{ij} (x_j - x_i),
           \qquad \dot x = -K (L \otimes I_D) x

with ``L = D - A`` the graph Laplacian. On a connected undirected graph all
agents converge to the average of the initial states (it is invariant since
``1^T L = 0``), at the rate ``K lambda_2(L)`` (algebraic connectivity).

The graph comes from a ``neighbors`` port (N, K) int64 (-1 padded; a
proximity graph, weights 1), a fixed ``adjacency`` matrix (weights
``a_ij``), or ``radius``/``k_max`` (neighbours computed inside the block by
a :class:`~avblocks.utility.spatial.NeighborSearch`; compiles).
Cost O(N K) per evaluation.

Reference: R. Olfati-Saber & R. M. Murray, "Consensus problems in networks of
agents with switching topology and time-delays", IEEE TAC 49(9), 2004;
M. Mesbahi & M. Egerstedt, *Graph Theoretic Methods in Multiagent Networks*
(2010), ch. 3.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.params import positive_scalar
from ._graph import NeighborSource, gather


def consensus_law(position, idx, weights, gain=1.0, xp=np):
    """``K sum_j w_ij (x_j - x_i)`` over padded neighbour lists ``idx`` (N, K)."""
    xj, mask = gather(position, idx, xp)
    w = xp.where(mask, weights, 0.0)[..., None]
    return gain * xp.sum(w * (xj - position[:, None, :]), axis=1)


class Consensus(Block):
    """Consensus / rendezvous velocity set-points for N single integrators.

    Ports
    -----
    position : in, (N, D).
    neighbors : in, (N, K) int64, -1 padded (only without adjacency/radius).
    velocity : out, (N, D).

    Parameters
    ----------
    n : int;  dim : int (D, default 2);  gain : float > 0 (1/s).
    adjacency : (N, N) array or sparse, optional — fixed weighted graph.
    radius, k_max : optional — compute proximity neighbours internally.

    Numeric parameters
    ------------------

    ``gain`` (and ``radius`` when given) are numeric parameters; the graph
    source, ``adjacency``, ``k_max``, ``n`` and ``dim`` are structural.

    Equations and references: module docstring.
    """

    def __init__(self, n, *, dim=2, gain=1.0, adjacency=None, radius=None, k_max=None):
        super().__init__()
        self.n = n = int(n)
        self.declare_parameter("gain", positive_scalar(gain, "Consensus", "gain"),
                               bounds=(1e-12, None), unit="1/s")
        self.declare_input("position", (n, int(dim)), unit="m")
        self.graph = NeighborSource(self, n, adjacency=adjacency, radius=radius,
                                    k_max=k_max)
        self.declare_output("velocity", (n, int(dim)), unit="m/s")

    def configure(self, inputs):
        self.graph.configure(inputs)

    def output(self, t, x, u, xp):
        p = u["position"]
        idx, w = self.graph.get(u, p, xp)
        return {"velocity": consensus_law(p, idx, w, self.gain, xp)}
