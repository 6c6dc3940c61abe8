"""A source whose value is set from outside the diagram at each control step."""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import count


class Action(Block):
    """The door through which a learning agent (or any outside caller) acts.

    Ports
    -----
    action : out, (N, dim)
        ``clip(value, low, high)``.

    State
    -----
    value : discrete (N, dim), held (no update changes it). An environment
        (:mod:`avblocks.rl`) writes the agents' actions into it before each
        control step; a plain run holds ``value0`` throughout.

    Parameters
    ----------
    n : int
        Number of agents.
    dim : int
        Action components per agent.
    low, high : float or (dim,)
        Limits per component (numeric parameters ``low``/``high``, shape
        ``(dim,)``); an environment's action space is the box they bound.
    value0 : array_like, optional
        Initial value (default zeros, clipped to the limits).

    Equations
    ---------
    ``action = min(max(value, low), high)`` (component-wise).

    Examples
    --------
    >>> import numpy as np
    >>> a = Action(2, 2, low=-1.0, high=1.0)
    >>> a.output(0.0, {"value": np.array([[2.0, 0.5], [-3.0, 0.0]])}, {}, np)["action"]
    array([[ 1. ,  0.5],
           [-1. ,  0. ]])
    """

    def __init__(self, n, dim=2, *, low=-1.0, high=1.0, value0=None):
        super().__init__()
        self.n = n = count(n, "Action", "n", lo=1)
        self.dim = dim = count(dim, "Action", "dim", lo=1)
        lo = np.broadcast_to(np.asarray(low, dtype=float), (dim,)).copy()
        hi = np.broadcast_to(np.asarray(high, dtype=float), (dim,)).copy()
        if np.any(hi < lo):
            raise ParameterError("high must be >= low", block="Action", param="high",
                                 expected=f">= {lo.tolist()}", found=hi.tolist())
        self.declare_parameter("low", lo, allow_inf=True)
        self.declare_parameter("high", hi, allow_inf=True)
        v0 = np.zeros((n, dim)) if value0 is None else np.asarray(value0, dtype=float)
        if v0.shape != (n, dim):
            v0 = np.broadcast_to(v0, (n, dim)).copy()
        self.declare_discrete_state("value", np.clip(v0, lo, hi), dtype="float64")
        self.declare_output("action", (n, dim))

    def output(self, t, x, u, xp):
        return {"action": xp.clip(x["value"], self.low, self.high)}

    def update(self, t, x, u, xp):
        return {}
