r"""Displacement-based formation control (Laplacian with desired offsets).

Equations
---------
.. math::  u_i = K \sum_{j \in N_i} a_{ij} \big((x_j - x_i) - (c_j - c_i)\big)

i.e. consensus on ``x_i - c_i``: on a connected undirected graph the agents
reach the formation ``c`` (N, D) up to a common translation, the average of
``x_i(0) - c_i``.

Reference: K.-K. Oh, M.-C. Park & H.-S. Ahn, "A survey of multi-agent
formation control", Automatica 53, 2015 (Section 4, displacement-based);
Mesbahi & Egerstedt (2010), ch. 6.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.params import finite_array, positive_scalar
from ._graph import NeighborSource
from .consensus import consensus_law


def displacement_formation_law(position, offsets, idx, weights, gain=1.0, xp=np):
    """``K sum_j w_ij ((x_j - x_i) - (c_j - c_i))``, (N, D)."""
    return consensus_law(position - offsets, idx, weights, gain, xp)


class DisplacementFormation(Block):
    """Formation by desired displacements for N single integrators.

    Ports
    -----
    position : in, (N, D);  neighbors : in (N, K) int64 (port mode only);
    velocity : out, (N, D).

    Parameters
    ----------
    offsets : (N, D)
        Desired positions ``c`` (any common translation).
    gain : float > 0
    adjacency, radius, k_max
        The graph source (see :class:`~avblocks.controllers.Consensus`).

    Numeric parameters
    ------------------

    ``offsets``, ``gain`` (and ``radius``) are numeric parameters.
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {'offsets': {'random_positions': {'n': '$agents',
                                                'area': [10, 10],
                                                'seed': '$seed'}}}

    def __init__(self, offsets, *, gain=1.0, adjacency=None, radius=None, k_max=None):
        super().__init__()
        c = finite_array(offsets, "DisplacementFormation", "offsets")
        if c.ndim != 2:
            c = finite_array(offsets, "DisplacementFormation", "offsets", shape=(-1, 2))
        self.declare_parameter("offsets", c, unit="m")
        self.n = n = c.shape[0]
        self.declare_parameter("gain", positive_scalar(gain, "DisplacementFormation",
                                                       "gain"),
                               bounds=(1e-12, None), unit="1/s")
        self.declare_input("position", c.shape, unit="m")
        self.graph = NeighborSource(self, n, adjacency=adjacency, radius=radius,
                                    k_max=k_max)
        self.declare_output("velocity", c.shape, unit="m/s")

    def configure(self, inputs):
        self.graph.configure(inputs)

    def output(self, t, x, u, xp):
        p = u["position"]
        idx, w = self.graph.get(u, p, xp)
        return {"velocity": displacement_formation_law(p, self.offsets,
                                                       idx, w, self.gain, xp)}
