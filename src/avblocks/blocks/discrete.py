"""Discrete-time blocks: unit delay and zero-order hold.

Both are periodic: they run at ``offset + k * period`` (a multiple of the
simulator's major step) and the simulator holds their outputs between hits.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError, ShapeError
from ._shapes import set_discrete_state, set_output


class UnitDelay(Block):
    """Output the input sampled one period earlier: ``y_k = u_{k-1}``.

    Ports
    -----
    u : in, any shape (not direct feedthrough: breaks algebraic loops)
    y : out, same shape as ``u``

    State
    -----
    x : discrete, the last input sample

    Parameters
    ----------
    initial : float or array_like
        Output before the first sample has gone through (``y_0``). A scalar
        is broadcast to the input's shape; an array fixes the port shape
        (useful inside feedback loops whose other blocks take their shape
        from the wiring).
    period : float
        Sample period (seconds).
    offset : float
        First hit, in ``[0, period)``.
    dtype : str, optional
        Dtype of the signal (default: that of ``initial``; bool and int
        signals stay as they are).

    Equations
    ---------
    y_k = x_k;  x_{k+1} = u_k;  x_0 = initial  (the z^-1 block)

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Clock(), name="c")
    >>> z = d.add(UnitDelay(-1.0, period=0.5), name="z")
    >>> d.connect(c.y, z.u)
    >>> av.simulate(d, 1.5, dt=0.25, log=[z.y])[z.y]
    array([-1. , -1. ,  0. ,  0. ,  0.5,  0.5,  1. ])
    """

    def __init__(self, initial=0.0, period=1.0, offset=0.0, *, dtype=None):
        super().__init__()
        a = np.asarray(initial)
        if a.dtype.kind not in "biuf":
            raise ParameterError("initial must be numeric or boolean", block="UnitDelay",
                                 param="initial", found=repr(initial)[:80])
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ParameterError("initial must be finite", block="UnitDelay",
                                 param="initial", found=a)
        if dtype is not None:
            a = a.astype(dtype)
        elif a.dtype.kind in "iu":
            a = a.astype(float)    # integer literals such as 0 mean a float signal
        self.initial = a
        self.declare_periodic(period, offset)
        shape = a.shape if a.ndim > 0 else None
        self.declare_input("u", shape, a.dtype.name, feedthrough=False)
        self.declare_output("y", shape, a.dtype.name)
        if shape is not None:
            self.declare_discrete_state("x", a)

    def configure(self, inputs):
        p = inputs["u"]
        if self.initial.ndim > 0 and self.initial.shape != p.shape:
            raise ShapeError("initial value and input have different shapes",
                             block="UnitDelay", port="u", expected=self.initial.shape,
                             found=p.shape)
        dtype = np.result_type(self.initial.dtype, np.dtype(p.dtype))
        x0 = np.broadcast_to(self.initial, p.shape).astype(dtype)
        set_discrete_state(self, "x", x0, dtype=dtype, agents=p.agents)
        set_output(self, "y", p.shape, dtype.name, p.agents)

    def output(self, t, x, u, xp):
        return {"y": x["x"]}

    def update(self, t, x, u, xp):
        return {"x": xp.asarray(u["u"], dtype=x["x"].dtype)}


class ZeroOrderHold(Block):
    """Sample the input at each hit and hold it until the next.

    Ports
    -----
    u : in, any shape (direct feedthrough)
    y : out, same shape as ``u``

    Parameters
    ----------
    period : float
        Sample period (seconds), a multiple of the major step.
    offset : float
        First hit, in ``[0, period)``. Before it the output holds the input
        sampled at the start time.

    Equations
    ---------
    y(t) = u(t_k)  for  t_k <= t < t_k + period,  t_k = offset + k * period

    The block is stateless: the simulator computes a periodic block's outputs
    at its hits only, from the inputs at that instant, and holds them through
    the major steps and solver stages in between.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Clock(), name="c")
    >>> h = d.add(ZeroOrderHold(0.5), name="h")
    >>> d.connect(c.y, h.u)
    >>> av.simulate(d, 1.5, dt=0.25, log=[h.y])[h.y]
    array([0. , 0. , 0.5, 0.5, 1. , 1. , 1.5])
    """

    def __init__(self, period=1.0, offset=0.0):
        super().__init__()
        self.declare_periodic(period, offset)
        self.declare_input("u")
        self.declare_output("y")

    def configure(self, inputs):
        p = inputs["u"]
        set_output(self, "y", p.shape, p.dtype, p.agents)

    def output(self, t, x, u, xp):
        return {"y": u["u"]}
