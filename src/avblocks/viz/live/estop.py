"""An emergency-stop source the live view's Stop button drives."""

from __future__ import annotations

from ...core.block import Block


class EStop(Block):
    """Emergency-stop signal for N robots, set by a numeric parameter.

    Ports
    -----
    estop : out, (N,) bool
        True for every robot once the parameter ``estop`` is >= 0.5.

    Parameters
    ----------
    n : int
        Number of robots.
    estop : float in [0, 1]
        Numeric parameter (``"<name>.estop"``); the live view's Stop button
        sets every parameter named ``estop`` to 1 and takes one more step
        before ending the run, so wiring this block to a robot interface's
        ``estop`` input (``interfaces.ros2``, ``estop=True``) stops the
        robots from the page.

    Examples
    --------
    >>> import numpy as np
    >>> b = EStop(3)
    >>> b.output(0.0, {}, {}, np)["estop"].tolist()
    [False, False, False]
    >>> b.set_parameter("estop", 1.0)
    >>> b.output(0.0, {}, {}, np)["estop"].tolist()
    [True, True, True]
    """

    def __init__(self, n, estop=0.0):
        super().__init__()
        self.n = int(n)
        self.declare_parameter("estop", float(estop), bounds=(0.0, 1.0),
                               doc="1 stops every robot")
        self.declare_output("estop", (self.n,), dtype="bool", doc="stop every robot")

    def output(self, t, x, u, xp):
        return {"estop": xp.broadcast_to(self.estop >= 0.5, (self.n,))}
