"""Communication between neighbouring agents: a lossy, delayed channel and
gossip (a flag or value spreading through contacts).

Both blocks find who can hear whom with a k-d tree (range ``radius``,
inclusive), draw packet losses from their own random key (so a run is
repeatable from its seed) and run in NumPy/SciPy (not JAX-traceable).

Used for information propagation (AVLib paper, case study IV.B: scouts
propagating information among ~500 agents in the nest).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core import rng as _rng
from ..core.block import Block
from ..core.errors import ParameterError
from ._common import agent_count, declare_agents_input, maybe_periodic
from .collision import _first_index
from .neighbors import radius_neighbors


def _probability(p, block):
    p = float(p)
    if not (0.0 <= p <= 1.0):
        raise ParameterError("probability must lie in [0, 1]", block=block,
                             param="p_loss", expected="[0, 1]", found=p)
    return p


class CommChannel(Block):
    """Messages between neighbours with range, packet loss and latency.

    Every agent broadcasts its ``message`` row at each step (each sample hit
    with ``period``). Agent ``i`` hears up to ``K`` nearest agents within
    ``radius`` (range checked when the message is sent); each link loses the
    packet independently with probability ``p_loss``; a message sent at step
    ``k`` is delivered at step ``k + latency``.

    Ports
    -----
    pose : in, (N, 3)  (or ``position`` (N, 2) with input="position")
    message : in, (N, D)
        What each agent sends now.
    sender : out, (N, K) int64
        Who the delivered messages come from, nearest first, -1 where no
        message arrived (no neighbour in range, or packet lost).
    received : out, (N, K, D)
        The delivered messages (0 where ``sender`` is -1).

    State
    -----
    key : random key; with ``latency >= 1`` a delay line ``line_sender``
    (latency, N, K) and ``line_message`` (latency, N, K, D): slot 0 is
    delivered next.

    Parameters
    ----------
    n : int
    radius : float
        Communication range [m] (inclusive). Numeric parameter.
    msg_dim : int
        ``D``, the width of a message.
    k : int, optional
        Most messages received per agent (default ``min(n - 1, 16)``).
    p_loss : float
        Packet-loss probability per link and step, in [0, 1]. Numeric
        parameter (``"comm.p_loss"``).
    latency : int
        Delay in steps (sample hits), >= 0. With 0 the inputs feed straight
        through (beware of algebraic loops); the default 1 breaks them.
    input : "pose" or "position"
    period : float, optional
        Discrete block with this period: one delivery per hit, latency
        counted in hits. Without it, one delivery per major step.

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import CommChannel
    >>> ch = CommChannel(2, radius=2.0, msg_dim=1, latency=0, input="position")
    >>> u = {"position": np.array([[0.0, 0], [1, 0]]), "message": np.array([[5.0], [7.0]])}
    >>> y = ch.output(0.0, ch.initial_state(), u, np)
    >>> y["sender"].tolist(), y["received"][:, 0, 0].tolist()
    ([[1], [0]], [7.0, 5.0])
    """

    #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
    traceable = False

    def __init__(self, n, *, radius, msg_dim=1, k=None, p_loss=0.0, latency=1,
                 input="pose", period=None):
        super().__init__()
        name = "CommChannel"
        self.n = n = agent_count(n, name)
        if k is None:
            k = max(1, min(n - 1, 16))
        self.k = k = agent_count(k, name)
        if not float(radius) > 0:
            raise ParameterError("radius must be > 0", block=name, param="radius",
                                 found=radius)
        self.declare_parameter("radius", float(radius), bounds=(1e-12, None),
                               allow_inf=True, unit="m")
        self.d = d = agent_count(msg_dim, name)
        self.declare_parameter("p_loss", _probability(p_loss, name), bounds=(0, 1),
                               doc="probability that a message is lost")
        latency = int(latency)
        if latency < 0:
            raise ParameterError("latency must be >= 0 steps", block=name,
                                 param="latency", found=latency)
        self.latency = latency
        ft = latency == 0
        self.input = declare_agents_input(self, n, input, feedthrough=ft)
        self.declare_input("message", (n, d), doc="message each agent sends",
                           feedthrough=ft)
        self.declare_output("sender", (n, k), "int64",
                            doc="senders of delivered messages, -1 none")
        self.declare_output("received", (n, k, d), doc="delivered messages")
        self.declare_random_state("key")
        if latency:
            self.declare_discrete_state("line_sender",
                                        np.full((latency, n, k), -1, dtype=np.int64))
            self.declare_discrete_state("line_message", np.zeros((latency, n, k, d)))
        maybe_periodic(self, period)

    def deliver(self, pos, message, key):
        """One delivery: (sender (N, K), received (N, K, D)) for a random key."""
        idx, _ = radius_neighbors(np.asarray(pos)[:, :2], float(self.radius), self.k)
        if self.p_loss > 0:
            keep = _rng.uniform(key, idx.shape, np) >= float(self.p_loss)
            idx = np.where(keep, idx, -1)
        msg = np.asarray(message)[np.maximum(idx, 0)]
        msg = np.where((idx >= 0)[..., None], msg, 0.0)
        return idx, msg

    def output(self, t, x, u, xp):
        if self.latency == 0:
            _, sub = _rng.split(x["key"], np)
            s, m = self.deliver(u[self.input], u["message"], sub)
            return {"sender": s, "received": m}
        return {"sender": x["line_sender"][0], "received": x["line_message"][0]}

    def update(self, t, x, u, xp):
        key, sub = _rng.split(x["key"], np)
        if self.latency == 0:
            return {"key": key}
        s, m = self.deliver(u[self.input], u["message"], sub)
        return {"key": key,
                "line_sender": np.concatenate([x["line_sender"][1:], s[None]]),
                "line_message": np.concatenate([x["line_message"][1:], m[None]])}


def gossip_step(informed, pos, radius, p_loss=0.0, key=None, value=None):
    """One round of gossip: every informed agent tells every agent in range.

    Returns the new ``informed`` (N,) bool and, when ``value`` (N, D) is
    given, the new values (a newly informed agent takes the value of its
    lowest-index informed neighbour that reached it). Each directed link
    fails independently with probability ``p_loss`` (drawn from ``key``).
    """
    informed = np.asarray(informed, dtype=bool)
    pos = np.asarray(pos, dtype=float)[:, :2]
    n = len(informed)
    pairs = (cKDTree(pos).query_pairs(radius, output_type="ndarray")
             if n > 1 else np.zeros((0, 2), np.int64))
    src = np.concatenate([pairs[:, 0], pairs[:, 1]]).astype(np.int64)
    dst = np.concatenate([pairs[:, 1], pairs[:, 0]]).astype(np.int64)
    ok = informed[src] & ~informed[dst]
    if p_loss > 0 and len(src):
        ok &= _rng.uniform(key, (len(src),), np) >= p_loss
    new = informed.copy()
    new[dst[ok]] = True
    if value is None:
        return new, None
    first = _first_index(n, dst[ok], src[ok])
    got = first >= 0
    val = np.array(value, dtype=float, copy=True)
    val[got] = val[first[got]]
    return new, val


class Gossip(Block):
    """A flag (and optionally a value) spreading through contacts; latched.

    At each step (each hit with ``period``) every informed agent informs
    every agent within ``radius``; each directed contact fails with
    probability ``p_loss``. With ``p_loss = 0`` and a static connected
    contact graph, everyone is informed after exactly the seeds'
    eccentricity in hops (the graph diameter in the worst case).

    Ports
    -----
    pose : in, (N, 3)  (or ``position`` (N, 2) with input="position"), not
        direct feedthrough
    flag : in, (N,) bool
        Seeds: agents that learn the information now (from outside).
    value : in, (N, D), only with ``value_dim``
        The value a seeding agent carries.
    informed : out, (N,) bool
        ``informed_state | flag``.
    value : out, (N, D), only with ``value_dim``
        The value each informed agent carries (0 for uninformed agents).

    State
    -----
    informed : discrete (N,) bool; ``carried`` (N, D) with ``value_dim``;
    ``key``: random key.

    Equations
    ---------
    ``I_{k+1} = S_k  or  { j : exists i in S_k, |p_i - p_j| <= radius,
    link i->j not lost }`` with ``S_k = I_k or flag_k``.

    Parameters
    ----------
    n : int
    radius : float
        Contact range [m] (inclusive). Numeric parameter.
    p_loss : float
        Contact failure probability, [0, 1]. Numeric parameter.
    value_dim : int, optional
        Also spread a value of this width (a broadcast).
    input : "pose" or "position"
    period : float, optional
        Discrete block with this period.

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import Gossip
    >>> g = Gossip(3, radius=1.0, input="position")
    >>> u = {"position": np.array([[0.0, 0], [1, 0], [2, 0]]),
    ...      "flag": np.array([True, False, False])}
    >>> x = g.initial_state()
    >>> for _ in range(2):
    ...     x = {**x, **g.update(0.0, x, u, np)}
    >>> g.output(0.0, x, u, np)["informed"].tolist()
    [True, True, True]
    """

    #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
    traceable = False

    def __init__(self, n, *, radius, p_loss=0.0, value_dim=None, input="pose",
                 period=None):
        super().__init__()
        name = "Gossip"
        self.n = n = agent_count(n, name)
        if not float(radius) > 0:
            raise ParameterError("radius must be > 0", block=name, param="radius",
                                 found=radius)
        self.declare_parameter("radius", float(radius), bounds=(1e-12, None),
                               allow_inf=True, unit="m")
        self.declare_parameter("p_loss", _probability(p_loss, name), bounds=(0, 1),
                               doc="probability that a message is lost")
        self.value_dim = None if value_dim is None else agent_count(value_dim, name)
        self.input = declare_agents_input(self, n, input, feedthrough=False)
        self.declare_input("flag", (n,), "bool", doc="seeds: informed from outside")
        self.declare_output("informed", (n,), "bool", doc="informed agents (latched)")
        self.declare_discrete_state("informed", np.zeros(n, dtype=bool))
        if self.value_dim:
            self.declare_input("value", (n, self.value_dim), doc="value a seed carries")
            self.declare_output("value", (n, self.value_dim), doc="value carried")
            self.declare_discrete_state("carried", np.zeros((n, self.value_dim)))
        self.declare_random_state("key")
        maybe_periodic(self, period)

    def _seeded(self, x, u):
        inf = x["informed"] | u["flag"]
        if not self.value_dim:
            return inf, None
        val = np.where(x["informed"][:, None], x["carried"],
                       np.where(u["flag"][:, None], u["value"], 0.0))
        return inf, val

    def output(self, t, x, u, xp):
        inf, val = self._seeded(x, u)
        return {"informed": inf} if val is None else {"informed": inf, "value": val}

    def update(self, t, x, u, xp):
        key, sub = _rng.split(x["key"], np)
        inf, val = self._seeded(x, u)
        new, val = gossip_step(inf, u[self.input], float(self.radius), float(self.p_loss),
                               sub, val)
        out = {"key": key, "informed": new}
        if self.value_dim:
            out["carried"] = val
        return out


class Broadcast(Gossip):
    """:class:`Gossip` that also spreads a value (``value_dim`` defaults to 1).

    Ports
    -----
    As :class:`Gossip` with ``value_dim`` set: ``flag`` (N,) bool and
    ``value`` (N, value_dim) in; ``informed`` (N,) bool and ``value``
    (N, value_dim) out.

    Parameters
    ----------
    n, radius, value_dim
        As :class:`Gossip`.
    kw
        Any other keyword of :class:`Gossip` (loss, period, input...).

    Numeric parameters: ``radius`` and ``p_loss``, as :class:`Gossip`.
    """

    def __init__(self, n, *, radius, value_dim=1, **kw):
        super().__init__(n, radius=radius, value_dim=value_dim, **kw)
