"""The pursuit task: N pursuers catch a slower evader.

Blocks: :class:`PursuitTask` (observation, reward, capture), the evader's
scripted law :class:`Flee` and the pursuers' scripted law :class:`Chase`.
The case study that wires them is :mod:`avblocks.scenarios.pursuit`
(``pursuit.yaml``).

Reference: the pursuit-evasion ("predator-prey", "simple tag") task of the
multi-agent particle environments, R. Lowe et al., "Multi-Agent
Actor-Critic for Mixed Cooperative-Competitive Environments", NeurIPS 2017.
"""

from __future__ import annotations

from ..core.block import Block
from ..core.params import count
from .common import others_index


class PursuitTask(Block):
    """Observation, reward and capture of the pursuit task.

    Ports
    -----
    pursuers : in, (N, 2) [m]
    evader : in, (1, 2) [m]
    obs : out, (N, 4 + 2(N-1))
    reward : out, (N,)
    done : out, (N,) bool: captured
    success : out, (N,) bool: captured
    distance : out, () closest pursuer to the evader [m]

    Parameters
    ----------
    n : int
        Pursuers.
    half : float
        Half the side of the square arena [m] (scales the own position in
        the observation).
    capture : float
        Capture distance [m].

    Numeric parameters
    ------------------

    ``half`` and ``capture`` (scalars, read at every call:
    ``"task.capture"``...); ``n`` is structural.

    Equations
    ---------
    With ``p_i`` the pursuers and ``e`` the evader, ``d = min_i |e - p_i|``:

    - ``obs_i = [p_i / half, e - p_i, (p_j - p_i for j != i)]``;
    - ``reward_i = -0.1 d + 10 [d < capture]`` (shared);
    - ``done_i = success_i = [d < capture]``.

    Examples
    --------
    >>> import numpy as np
    >>> t = PursuitTask(2, half=1.0, capture=0.2)
    >>> y = t.output(0.0, {}, {"pursuers": np.array([[0.0, 0.0], [1.0, 0.0]]),
    ...                        "evader": np.array([[0.1, 0.0]])}, np)
    >>> bool(y["done"][0]), round(float(y["distance"]), 6)
    (True, 0.1)
    """

    example = {"n": "$agents"}
    parameter_info = {"n": {"bounds": [1, None]}}

    def __init__(self, n, *, half=1.5, capture=0.15):
        super().__init__()
        self.n = n = count(n, "PursuitTask", "n", lo=1)
        self.idx = others_index(n)
        self.declare_parameter("half", half, bounds=(0, None), unit="m")
        self.declare_parameter("capture", capture, bounds=(0, None), unit="m")
        self.declare_input("pursuers", (n, 2), unit="m")
        self.declare_input("evader", (1, 2), unit="m", agents=False)
        self.declare_output("obs", (n, 4 + 2 * (n - 1)))
        self.declare_output("reward", (n,))
        self.declare_output("done", (n,), "bool")
        self.declare_output("success", (n,), "bool")
        self.declare_output("distance", (), agents=False, unit="m")

    def output(self, t, x, u, xp):
        p, e = u["pursuers"], u["evader"]
        n = self.n
        rel = e - p                                             # (n, 2)
        rel_o = p[self.idx] - p[:, None, :]
        obs = xp.concatenate([p / self.half, rel, xp.reshape(rel_o, (n, -1))], axis=1)
        dmin = xp.min(xp.sqrt(xp.sum(rel * rel, -1) + 1e-12))
        caught = dmin < self.capture
        reward = xp.broadcast_to(-0.1 * dmin + 10.0 * caught, (n,))
        flag = xp.broadcast_to(caught, (n,))
        return {"obs": obs, "reward": reward, "done": flag, "success": flag, "distance": dmin}


def flee_velocity(pursuers, evader, half, speed, xp):
    """The evader's velocity (1, 2): :class:`Flee`'s law."""
    margin = 0.3 * half
    d = evader - pursuers                                       # (n, 2)
    r2 = xp.sum(d * d, -1, keepdims=True) + 1e-6
    away = xp.sum(d / r2, axis=0, keepdims=True)                # (1, 2)
    away = away / xp.sqrt(xp.sum(away * away) + 1e-12)
    # walls: push inwards within the margin, growing to 2 at the wall
    gap_hi = half - evader
    gap_lo = evader + half
    push = xp.clip((margin - gap_lo) / margin, 0.0, 1.0) - \
        xp.clip((margin - gap_hi) / margin, 0.0, 1.0)
    v = away + 2.0 * push
    nv = xp.sqrt(xp.sum(v * v) + 1e-12)
    return speed * v / xp.maximum(nv, 1e-6)


class Flee(Block):
    """The evader's scripted law: away from the pursuers, off the walls.

    Ports
    -----
    pursuers : in, (N, 2) [m]
    evader : in, (1, 2) [m]
    velocity : out, (1, 2) [m/s], of norm ``speed``

    Parameters
    ----------
    n : int
        Pursuers.
    half : float
        Half the side of the square arena [m].
    speed : float
        The evader's speed [m/s].

    Numeric parameters
    ------------------

    ``half`` (the walls, hence the margin ``0.3 half``) and ``speed``
    (scalars, read at every call: ``"flee.speed"``...); ``n`` is
    structural.

    Equations
    ---------
    With ``d_i = e - p_i``, ``a = sum_i d_i / (|d_i|^2 + 1e-6)`` (inverse
    squared distance weights), ``m = 0.3 half`` and per axis
    ``w = clip((m - (e + half)) / m, 0, 1) - clip((m - (half - e)) / m, 0, 1)``
    (a push inwards within ``m`` of a wall, 1 at the wall):
    ``v = a / |a| + 2 w`` and ``velocity = speed v / max(|v|, 1e-6)``.

    Examples
    --------
    >>> import numpy as np
    >>> f = Flee(1, half=10.0, speed=0.5)
    >>> f.output(0.0, {}, {"pursuers": np.array([[0.0, 0.0]]),
    ...                    "evader": np.array([[1.0, 0.0]])}, np)["velocity"].round(6)
    array([[0.5, 0. ]])
    """

    example = {"n": "$agents"}
    parameter_info = {"n": {"bounds": [1, None]}}

    def __init__(self, n, *, half=1.5, speed=0.7):
        super().__init__()
        self.n = n = count(n, "Flee", "n", lo=1)
        self.declare_parameter("half", half, bounds=(0, None), unit="m")
        self.declare_parameter("speed", speed, bounds=(0, None), unit="m/s")
        self.declare_input("pursuers", (n, 2), unit="m")
        self.declare_input("evader", (1, 2), unit="m", agents=False)
        self.declare_output("velocity", (1, 2), unit="m/s", agents=False)

    def output(self, t, x, u, xp):
        return {"velocity": flee_velocity(u["pursuers"], u["evader"], self.half,
                                          self.speed, xp)}


class Chase(Block):
    """The pursuers' scripted law: each heads straight at the evader.

    Ports
    -----
    pursuers : in, (N, 2) [m]
    evader : in, (1, 2) [m]
    cmd : out, (N, 2), unit vectors towards the evader

    Parameters
    ----------
    n : int
        Pursuers.

    Numeric parameters
    ------------------

    None: the law owns no number (the command is a unit vector; the
    pursuers' speed is the vehicles' or the task command's).

    Equations
    ---------
    ``cmd_i = (e - p_i) / sqrt(|e - p_i|^2 + 1e-12)`` (pure pursuit: the
    velocity points at the target's current position).

    Examples
    --------
    >>> import numpy as np
    >>> c = Chase(1)
    >>> c.output(0.0, {}, {"pursuers": np.array([[0.0, 0.0]]),
    ...                    "evader": np.array([[0.0, 2.0]])}, np)["cmd"].round(6)
    array([[0., 1.]])
    """

    example = {"n": "$agents"}
    parameter_info = {"n": {"bounds": [1, None]}}

    def __init__(self, n):
        super().__init__()
        self.n = n = count(n, "Chase", "n", lo=1)
        self.declare_input("pursuers", (n, 2), unit="m")
        self.declare_input("evader", (1, 2), unit="m", agents=False)
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        rel = u["evader"] - u["pursuers"]
        return {"cmd": rel / xp.sqrt(xp.sum(rel * rel, -1, keepdims=True) + 1e-12)}
