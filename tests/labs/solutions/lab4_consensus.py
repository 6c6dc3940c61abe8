"""Reference solution of lab 4 (kept with the tests, not in the template).

Lab 4: consensus and the graph Laplacian. Write `laplacian` and
MyConsensus.output, then run `avblocks lab check 4 lab4_consensus.py`.

N agents, single integrators dx_i/dt = u_i, talk over an undirected graph
with weights a_ij = a_ji >= 0 (a_ii = 0). The consensus law

    u_i = K sum_j a_ij (x_j - x_i)

is, stacked over the agents, u = -K L x with the graph Laplacian

    L = D - A,   D = diag(sum_j a_ij)   (the degrees).

L is symmetric with rows summing to zero, so the average of x never
changes; on a connected graph every x_i converges to that average, and the
disagreement x - mean decays like exp(-K lambda_2 t), lambda_2 the second
smallest eigenvalue of L (the algebraic connectivity).

Rules of the library: the agent axis comes first, compute with `xp`, never
loop over agents, never write into `u`.
"""

import numpy as np

import avblocks as av


def laplacian(adjacency):
    """The Laplacian D - A of a weighted undirected graph, (N, N)."""
    a = np.asarray(adjacency, dtype=float)
    return np.diag(a.sum(axis=1)) - a


class MyConsensus(av.Block):
    """Consensus of N agents in D dimensions.

    Ports: position (N, D) in; velocity (N, D) out.
    Parameters: adjacency (N, N), symmetric, zero diagonal; gain K (1/s).
    """

    def __init__(self, adjacency, gain=1.0, dim=2):
        super().__init__()
        self.adjacency = np.asarray(adjacency, dtype=float)
        self.n = len(self.adjacency)
        self.gain = float(gain)
        self.declare_input("position", (self.n, dim), unit="m")
        self.declare_output("velocity", (self.n, dim), unit="m/s")

    def output(self, t, x, u, xp):
        p = u["position"]
        lap = xp.asarray(laplacian(self.adjacency))
        return {"velocity": -self.gain * (lap @ p)}
