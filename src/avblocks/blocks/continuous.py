"""Continuous-time linear blocks."""

from __future__ import annotations

from ..core.block import Block
from ..core.params import finite_array


class Integrator(Block):
    """``dx/dt = u``, ``y = x``, starting at ``x0``.

    Ports
    -----
    u : in, shape of ``x0`` (not direct feedthrough)
    y : out, shape of ``x0``

    State
    -----
    x : continuous, shape of ``x0``

    Parameters
    ----------
    x0 : array_like
        Initial value; fixes the shapes.
    agents : bool
        Whether the first axis of ``x0`` counts agents.
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"x0": {"zeros": {"shape": ["$agents", 2]}}}

    def __init__(self, x0, *, agents=True):
        super().__init__()
        x0 = finite_array(x0, "Integrator", "x0")
        ag = agents and x0.ndim > 0
        self.declare_continuous_state("x", x0, agents=ag)
        self.declare_input("u", x0.shape, feedthrough=False, agents=ag)
        self.declare_output("y", x0.shape, agents=ag)

    def output(self, t, x, u, xp):
        return {"y": x["x"]}

    def derivative(self, t, x, u, xp):
        return {"x": u["u"]}
