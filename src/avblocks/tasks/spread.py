"""The spread task: N agents cover N landmarks without colliding.

Blocks: :class:`SpreadTask` (observation, reward, success); the scripted
controller is a :class:`~avblocks.controllers.HolonomicPointToPoint` to the
landmark :func:`assign_landmarks` gives each agent. The case study that
wires them is :mod:`avblocks.scenarios.spread` (``spread.yaml``).

Reference: the "simple spread" (cooperative navigation) task of the
multi-agent particle environments, R. Lowe et al., "Multi-Agent
Actor-Critic for Mixed Cooperative-Competitive Environments", NeurIPS 2017.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.params import count
from .common import others_index, pairwise


class SpreadTask(Block):
    """Observation, reward and success of the spread task.

    Ports
    -----
    position : in, (N, 2) [m]
    landmarks : in, (N, 2) [m]
    obs : out, (N, 2 + 2N + 2(N-1))
    reward : out, (N,)
    done : out, (N,) bool (always false)
    success : out, () bool: every landmark covered within ``cover``.

    Parameters
    ----------
    n : int
        Agents (and landmarks).
    radius : float
        Agent radius [m]: two agents closer than ``2 radius`` collide.
    cover : float
        A landmark is covered by an agent within this distance [m].
    collision : float
        Penalty per colliding neighbour.

    Numeric parameters
    ------------------

    ``radius``, ``cover`` and ``collision`` (scalars, read at every call:
    ``"task.cover"``...); ``n`` is structural.

    Equations
    ---------
    With ``p_i`` the agents and ``l_k`` the landmarks:

    - ``obs_i = [p_i, (l_k - p_i for all k), (p_j - p_i for j != i)]``;
    - ``reward_i = -sum_k min_j |p_j - l_k| - collision #{j != i: |p_j - p_i|
      < 2 radius}``;
    - ``success = all_k (min_j |p_j - l_k| < cover)``.

    Examples
    --------
    >>> import numpy as np
    >>> t = SpreadTask(2, cover=0.1)
    >>> p = np.array([[0.0, 0.0], [1.0, 0.0]])
    >>> y = t.output(0.0, {}, {"position": p, "landmarks": p[::-1]}, np)
    >>> bool(y["success"]), float(abs(y["reward"]).max())
    (True, 0.0)
    """

    example = {"n": "$agents"}
    parameter_info = {"n": {"bounds": [1, None]}}

    def __init__(self, n, *, radius=0.1, cover=0.1, collision=1.0):
        super().__init__()
        self.n = n = count(n, "SpreadTask", "n", lo=1)
        self.idx = others_index(n)
        self.declare_parameter("radius", radius, bounds=(0, None), unit="m")
        self.declare_parameter("cover", cover, bounds=(0, None), unit="m")
        self.declare_parameter("collision", collision, bounds=(0, None))
        self.declare_input("position", (n, 2), unit="m")
        self.declare_input("landmarks", (n, 2), unit="m")
        self.declare_output("obs", (n, 2 + 2 * n + 2 * (n - 1)))
        self.declare_output("reward", (n,))
        self.declare_output("done", (n,), "bool")
        self.declare_output("success", (), "bool", agents=False)

    def output(self, t, x, u, xp):
        p, lm = u["position"], u["landmarks"]
        n = self.n
        rel_l = lm[None, :, :] - p[:, None, :]                    # (n, L, 2)
        rel_o = p[self.idx] - p[:, None, :]                       # (n, n-1, 2)
        obs = xp.concatenate([p, xp.reshape(rel_l, (n, -1)), xp.reshape(rel_o, (n, -1))],
                             axis=1)
        dl = xp.sqrt(xp.sum(rel_l * rel_l, axis=-1))              # (agent, landmark)
        near = xp.min(dl, axis=0)                                 # per landmark
        hits = xp.sum(pairwise(p, xp) < 2 * self.radius, axis=1)
        reward = -xp.sum(near) - self.collision * hits
        return {"obs": obs, "reward": reward, "done": xp.zeros((n,), dtype=bool),
                "success": xp.all(near < self.cover)}


def assign_landmarks(positions, landmarks):
    """Each agent's landmark, (N, 2): the assignment of agents to landmarks
    with the least total distance (the Hungarian method,
    ``scipy.optimize.linear_sum_assignment``; H. W. Kuhn, "The Hungarian
    method for the assignment problem", 1955). NumPy, at build time: the
    scripted controller's waypoints."""
    from scipy.optimize import linear_sum_assignment
    p = np.asarray(positions, float)
    lm = np.asarray(landmarks, float)
    cost = np.linalg.norm(p[:, None, :] - lm[None, :, :], axis=-1)
    _, col = linear_sum_assignment(cost)
    return lm[col]
