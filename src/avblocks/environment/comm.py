"""Communication between neighbouring agents: a lossy, delayed channel and
gossip (a flag or value spreading through contacts).

Both blocks find who can hear whom with a traceable cell-list search
(:class:`avblocks.utility.spatial.NeighborSearch`, range ``radius``,
inclusive) and draw packet losses from their own random key with the
counter-based stream of :mod:`avblocks.core.rng`: the loss of link ``i -> j``
at a step is ``uniform_at(key, i, j) < p_loss``, a function of the key and
the link only. So a run is repeatable from its seed, and the NumPy engine
and the compiled (JAX) engine deliver the same messages for the same seed.
All state has static shapes (latency as a fixed-length delay line); both
blocks compile.

Compiled runs need a static plan of the search (cell capacity): the
compiled engine plans it from the initial positions, or pass ``capacity=``
(most agents per cell of edge ``radius``; see :mod:`avblocks.utility.spatial`).

Used for information propagation (AVLib paper, case study IV.B: scouts
propagating information among ~500 agents in the nest).
"""

from __future__ import annotations

import numpy as np

from ..core import rng as _rng
from ..core.block import Block
from ..core.errors import ParameterError
from ..utility.spatial import NeighborSearch
from ._common import agent_count, declare_agents_input, maybe_periodic


def _int(xp):
    """The index dtype of an output: int64 (the default int of a trace without x64)."""
    return np.int64 if xp is np else xp.asarray(0).dtype


def _reach(radius, reach, block):
    r = float(radius) if reach is None else float(reach)
    if not r >= float(radius):
        raise ParameterError("reach must be >= radius", block=block, param="reach",
                             expected=f">= {float(radius)}", found=reach)
    return r


def _link_lost(key, src, dst, p_loss, xp):
    """True where link ``src -> dst`` loses its packet (``src`` may be -1)."""
    u = _rng.uniform_at(key, xp.maximum(src, 0), dst, xp)
    return u < p_loss


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
    ``radius`` (range checked when the message is sent; ties in distance by
    the smaller index); each link loses the packet independently with
    probability ``p_loss`` (link ``s -> i`` is lost when
    ``rng.uniform_at(key, s, i) < p_loss``); a message sent at step ``k`` is
    delivered at step ``k + latency``. Traceable: the NumPy and compiled
    engines deliver the same messages for the same seed.

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
    capacity : int, optional
        Static cell capacity of the neighbour search for compiled runs
        (default: planned by the compiled engine from the first positions).
    reach : float, optional
        The largest ``radius`` a compiled run may use (cell edge of the
        search; default ``radius``). Raise it to vary ``radius`` at run time
        (``params=``, ensembles); a larger radius than ``reach`` is reported
        as an overflow.

    Examples
    --------
    >>> import numpy as np
    >>> from avblocks.environment import CommChannel
    >>> ch = CommChannel(2, radius=2.0, msg_dim=1, latency=0, input="position")
    >>> u = {"position": np.array([[0.0, 0], [1, 0]]), "message": np.array([[5.0], [7.0]])}
    >>> y = ch.output(0.0, ch.initial_state(), u, np)
    >>> y["sender"].tolist(), y["received"][:, 0, 0].tolist()
    ([[1], [0]], [7.0, 5.0])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "radius": 5.0}

    def __init__(self, n, *, radius, msg_dim=1, k=None, p_loss=0.0, latency=1,
                 input="pose", period=None, capacity=None, reach=None):
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
        self.search = NeighborSearch(_reach(radius, reach, name), points=self.input,
                                     capacity=capacity)
        if latency:
            self.declare_discrete_state("line_sender",
                                        np.full((latency, n, k), -1, dtype=np.int64))
            self.declare_discrete_state("line_message", np.zeros((latency, n, k, d)))
        maybe_periodic(self, period)

    def deliver(self, pos, message, key, xp=np):
        """One delivery: (sender (N, K), received (N, K, D)) for a random key."""
        pos = xp.asarray(pos)[:, :2]
        idx, _ = self.search.nearest(pos, self.radius, self.k, xp=xp)
        if not (xp is np and float(self.p_loss) == 0.0):
            dst = xp.arange(self.n, dtype=np.int32)[:, None]
            idx = xp.where(_link_lost(key, idx, dst, self.p_loss, xp), -1, idx)
        idx = idx.astype(_int(xp))
        msg = xp.asarray(message)[xp.maximum(idx, 0)]
        msg = xp.where((idx >= 0)[..., None], msg, 0.0)
        return idx, msg

    def output(self, t, x, u, xp):
        if self.latency == 0:
            _, sub = _rng.split(x["key"], xp)
            s, m = self.deliver(u[self.input], u["message"], sub, xp)
            return {"sender": s, "received": m}
        return {"sender": x["line_sender"][0], "received": x["line_message"][0]}

    def update(self, t, x, u, xp):
        key, sub = _rng.split(x["key"], xp)
        if self.latency == 0:
            return {"key": key}
        s, m = self.deliver(u[self.input], u["message"], sub, xp)
        return {"key": key,
                "line_sender": xp.concatenate([x["line_sender"][1:],
                                               s[None].astype(x["line_sender"].dtype)]),
                "line_message": xp.concatenate([x["line_message"][1:],
                                                m[None].astype(x["line_message"].dtype)])}


def gossip_step(informed, pos, radius, p_loss=0.0, key=None, value=None, xp=np,
                search=None):
    """One round of gossip: every informed agent tells every agent in range.

    Returns the new ``informed`` (N,) bool and, when ``value`` (N, D) is
    given, the new values (a newly informed agent takes the value of its
    lowest-index informed neighbour that reached it). Each directed link
    ``i -> j`` fails independently with probability ``p_loss``: when
    ``rng.uniform_at(key, i, j) < p_loss``. ``search`` is the
    :class:`NeighborSearch` to use (a fresh one of reach ``radius`` if None;
    a compiled caller passes a planned one).
    """
    informed = xp.asarray(informed).astype(bool)
    pos = xp.asarray(pos)[:, :2]
    n = informed.shape[0]
    if search is None:
        search = NeighborSearch(float(radius), points="position")
    src, _ = search.within(pos, radius, xp=xp)             # (N, M): who reaches row j
    dst = xp.arange(n, dtype=np.int32)[:, None]
    ok = (src >= 0) & informed[xp.maximum(src, 0)] & ~informed[:, None]
    if xp is np:
        # NumPy: draw only where it matters (the draw of a link does not
        # depend on which other links are drawn: same numbers as traced)
        if float(p_loss) > 0.0:
            if key is None:
                raise ParameterError("gossip with p_loss > 0 needs a random key",
                                     param="key")
            r, c = np.nonzero(ok)
            ok = ok.copy()
            ok[r, c] = ~_link_lost(key, src[r, c], r, p_loss, np)
    else:
        ok = ok & ~_link_lost(key, src, dst, p_loss, xp)
    reached = xp.any(ok, axis=1)
    new = informed | reached
    if value is None:
        return new, None
    big = np.iinfo(np.int32).max
    first = xp.min(xp.where(ok, src, big), axis=1) if src.shape[1] else \
        xp.full((n,), big, dtype=np.int32)
    val = xp.asarray(value)
    val = xp.where(reached[:, None], val[xp.minimum(first, n - 1)], val)
    return new, val


class Gossip(Block):
    """A flag (and optionally a value) spreading through contacts; latched.

    At each step (each hit with ``period``) every informed agent informs
    every agent within ``radius``; each directed contact fails with
    probability ``p_loss`` (as in :func:`gossip_step`, keyed by the link so
    the NumPy and compiled engines agree). With ``p_loss = 0`` and a static
    connected contact graph, everyone is informed after exactly the seeds'
    eccentricity in hops (the graph diameter in the worst case). Traceable.

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
    capacity : int, optional
        Static cell capacity of the neighbour search for compiled runs
        (default: planned by the compiled engine from the first positions).
    reach : float, optional
        The largest ``radius`` a compiled run may use (cell edge of the
        search; default ``radius``). Raise it to vary ``radius`` at run time
        (``params=``, ensembles); a larger radius than ``reach`` is reported
        as an overflow.

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

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "radius": 5.0}

    def __init__(self, n, *, radius, p_loss=0.0, value_dim=None, input="pose",
                 period=None, capacity=None, reach=None):
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
        self.search = NeighborSearch(_reach(radius, reach, name), points=self.input,
                                     capacity=capacity)
        maybe_periodic(self, period)

    def _seeded(self, x, u, xp):
        inf = x["informed"] | u["flag"]
        if not self.value_dim:
            return inf, None
        val = xp.where(x["informed"][:, None], x["carried"],
                       xp.where(u["flag"][:, None], u["value"], 0.0))
        return inf, val

    def output(self, t, x, u, xp):
        inf, val = self._seeded(x, u, xp)
        return {"informed": inf} if val is None else {"informed": inf, "value": val}

    def update(self, t, x, u, xp):
        key, sub = _rng.split(x["key"], xp)
        inf, val = self._seeded(x, u, xp)
        new, val = gossip_step(inf, u[self.input], self.radius, self.p_loss, sub, val,
                               xp=xp, search=self.search)
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

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "radius": 5.0}

    def __init__(self, n, *, radius, value_dim=1, **kw):
        super().__init__(n, radius=radius, value_dim=value_dim, **kw)
