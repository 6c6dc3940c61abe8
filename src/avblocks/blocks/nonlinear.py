"""Static and rate nonlinearities: saturation, dead zone, rate limiter.

Their ports take the shape of what is wired to them; bounds and rates may be
scalars or arrays that broadcast to the signal (per component, per agent).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block, Periodic
from ..core.errors import ParameterError
from ..core.params import finite_array
from ._shapes import bounds, broadcast_to_input, set_discrete_state, set_output


def _ordered(lower, upper, block):
    lo = bounds(lower, block, "lower")
    hi = bounds(upper, block, "upper")
    try:
        ok = bool(np.all(lo <= hi))
    except ValueError:
        raise ParameterError("lower and upper do not broadcast together", block=block,
                             param="upper", expected=lo.shape, found=hi.shape) from None
    if not ok:
        raise ParameterError("lower must not exceed upper", block=block, param="lower",
                             expected=f"<= upper ({hi})", found=lo)
    return lo, hi


class _Bounded(Block):
    """Shared set-up of the elementwise blocks with a ``[lower, upper]`` band:
    one input ``u``, one output ``y`` of the same shape."""

    def __init__(self, lower, upper):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        lo, hi = _ordered(lower, upper, type(self).__name__)
        self.declare_parameter("lower", lo, allow_inf=True)
        self.declare_parameter("upper", hi, allow_inf=True)
        self.declare_input("u")
        self.declare_output("y")

    def configure(self, inputs):
        for p in ("lower", "upper"):
            broadcast_to_input(getattr(self, p), inputs["u"], type(self).__name__, p)
        set_output(self, "y", inputs["u"].shape, "float64", inputs["u"].agents)


class Saturation(_Bounded):
    """Clip a signal to ``[lower, upper]``.

    Ports
    -----
    u : in, any shape
    y : out, same shape as ``u``

    Parameters
    ----------
    lower, upper : float or array_like
        Bounds, broadcast against ``u`` (e.g. ``[v_min, w_min]`` for an
        ``(N, 2)`` command); ``-inf``/``inf`` give a one-sided limit.
        Numeric parameters (their given shapes).

    Equations
    ---------
    y = min(max(u, lower), upper)

    Examples
    --------
    >>> import numpy as np
    >>> Saturation(-1.0, 2.0).output(0.0, {}, {"u": np.array([-3.0, 0.5, 7.0])}, np)["y"]
    array([-1. ,  0.5,  2. ])
    """

    def __init__(self, lower=-1.0, upper=1.0):
        super().__init__(lower, upper)

    def output(self, t, x, u, xp):
        return {"y": xp.clip(u["u"], self.lower, self.upper)}


class DeadZone(_Bounded):
    """Zero output inside ``[lower, upper]``, shifted input outside it.

    Ports
    -----
    u : in, any shape
    y : out, same shape as ``u``

    Parameters
    ----------
    lower, upper : float or array_like
        Start and end of the dead zone, broadcast against ``u``. Numeric
        parameters (their given shapes).

    Equations
    ---------
    y = u - upper if u > upper;  0 if lower <= u <= upper;  u - lower if u < lower
    (Simulink's Dead Zone block.)

    Examples
    --------
    >>> import numpy as np
    >>> DeadZone(-1.0, 1.0).output(0.0, {}, {"u": np.array([-3.0, 0.5, 7.0])}, np)["y"]
    array([-2.,  0.,  6.])
    """

    def __init__(self, lower=-0.5, upper=0.5):
        super().__init__(lower, upper)

    def output(self, t, x, u, xp):
        v = u["u"]
        return {"y": xp.where(v > self.upper, v - self.upper,
                              xp.where(v < self.lower, v - self.lower, 0.0 * v))}


class RateLimiter(Block):
    """Limit how fast a signal may rise and fall.

    Ports
    -----
    u : in, any shape (direct feedthrough)
    y : out, same shape as ``u``

    State
    -----
    prev : discrete, the previous output ``y_{k-1}``
    t : discrete, time of the previous sample
    started : discrete bool, false before the first sample

    Parameters
    ----------
    rising : float or array_like, >= 0
        Largest rate of increase (units of ``u`` per second).
    falling : float or array_like, <= 0
        Largest rate of decrease, a non-positive number (Simulink convention).
        Default: ``-rising``.
    initial : float or array_like, optional
        Output at the first sample. Default: the input at the first sample.
    period, offset : float, optional
        Sample the block periodically (``dt = period``). Without a period the
        block samples at every major step and ``dt`` is the time elapsed
        since the previous major step (inside solver stages the output ramps
        with the elapsed time, so a continuous consumer sees a rate-limited
        signal too).

    Numeric parameters
    ------------------

    ``rising`` and ``falling`` are numeric parameters (a default ``falling``
    is set once to ``-rising``: change both to keep them symmetric);
    ``initial`` is an initial value, the period structural.

    Equations
    ---------
    y_0 = initial (or u_0);
    y_k = y_{k-1} + clip(u_k - y_{k-1}, falling * dt, rising * dt)

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> s = d.add(av.blocks.Step(0.0, 0.0, 1.0, agents=False), name="s")
    >>> r = d.add(RateLimiter(2.0, initial=0.0, period=0.1), name="r")
    >>> d.connect(s.y, r.u)
    >>> np.round(av.simulate(d, 0.6, dt=0.1, log=[r.y])[r.y], 6)
    array([0. , 0.2, 0.4, 0.6, 0.8, 1. , 1. ])
    """

    def __init__(self, rising=1.0, falling=None, *, initial=None, period=None,
                 offset=0.0):
        super().__init__()
        rising = finite_array(rising, "RateLimiter", "rising")
        if np.any(rising < 0):
            raise ParameterError("rising rate must be >= 0", block="RateLimiter",
                                 param="rising", expected=">= 0", found=rising)
        if falling is None:
            falling = -rising
        else:
            falling = finite_array(falling, "RateLimiter", "falling")
            if np.any(falling > 0):
                raise ParameterError(
                    "falling rate must be <= 0", block="RateLimiter", param="falling",
                    expected="<= 0", found=falling,
                    hint="give the largest decrease per second as a negative number")
        self.declare_parameter("rising", rising, bounds=(0, None))
        self.declare_parameter("falling", falling, bounds=(None, 0))
        self.initial = None if initial is None else finite_array(
            initial, "RateLimiter", "initial")
        if period is not None:
            self.declare_periodic(period, offset)
        self.declare_input("u")
        self.declare_output("y")
        self.declare_discrete_state("t", 0.0, agents=False)
        self.declare_discrete_state("started", False, dtype=bool, agents=False)

    def configure(self, inputs):
        p = inputs["u"]
        for name in ("rising", "falling") + (("initial",) if self.initial is not None
                                             else ()):
            broadcast_to_input(getattr(self, name), p, "RateLimiter", name)
        y0 = np.zeros(p.shape) if self.initial is None else np.broadcast_to(
            self.initial, p.shape).copy()
        set_discrete_state(self, "prev", y0, dtype=float, agents=p.agents)
        set_output(self, "y", p.shape, "float64", p.agents)

    def _next(self, t, x, u, xp):
        if isinstance(self.sample_time, Periodic):
            dt = self.sample_time.period
        else:
            dt = t - x["t"]
        prev = x["prev"]
        lim = prev + xp.clip(u["u"] - prev, self.falling * dt, self.rising * dt)
        first = u["u"] if self.initial is None else prev
        return xp.where(x["started"], lim, first)

    def output(self, t, x, u, xp):
        return {"y": self._next(t, x, u, xp)}

    def update(self, t, x, u, xp):
        return {"prev": self._next(t, x, u, xp), "t": xp.asarray(t, dtype=float),
                "started": xp.asarray(True)}
