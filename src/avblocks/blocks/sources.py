"""Sources: constant, clock, step and sine signals.

Each source takes its value's shape from its parameters; a per-agent signal
is simply an array whose first axis is the agent axis.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.params import finite_array


class Constant(Block):
    """A constant signal.

    Ports
    -----
    y : out, shape of ``value``

    Parameters
    ----------
    value : array_like
        The value (its first axis is the agent axis when ``agents`` is true).
    agents : bool
        Whether the first axis of ``value`` counts agents.
    unit : str
        Unit of the signal, for plots and files.

    A float ``value`` is a numeric parameter (``"c.value"``, its shape
    fixed); an integer or boolean one is structural.
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"value": {"zeros": {"shape": ["$agents", 2]}}}

    def __init__(self, value, *, agents=True, unit=""):
        super().__init__()
        v = np.asarray(value)
        if v.dtype.kind not in "biu":
            v = self.declare_parameter("value", finite_array(value, "Constant", "value"))
        else:
            self.value = v
        self.declare_output("y", v.shape, v.dtype.name, unit=unit,
                            agents=agents and v.ndim > 0)

    def output(self, t, x, u, xp):
        return {"y": xp.asarray(self.value)}


class Clock(Block):
    """Simulation time as a signal.

    Ports
    -----
    y : out, shape (), seconds
    """

    def __init__(self):
        super().__init__()
        self.declare_output("y", (), unit="s", agents=False)

    def output(self, t, x, u, xp):
        return {"y": xp.asarray(t, dtype=float)}


class Step(Block):
    """A step: ``before`` for t < ``time``, ``after`` from then on.

    Ports
    -----
    y : out, shape of ``after``

    Parameters
    ----------
    time : float
        Step time (s).
    before, after : array_like
        Values before and from the step on (``before`` broadcast to ``after``).
    agents : bool
        Whether the first axis counts agents.

    Numeric parameters
    ------------------

    ``time``, ``before`` and ``after`` are numeric parameters.

    Equations
    ---------
    y(t) = before + (after - before) * [t >= time]

    Under a fixed-step solver a ``time`` inside a major step splits that
    step at ``time`` (see :meth:`switch_times`), so RK4 stays fourth order.
    """

    def __init__(self, time=1.0, before=0.0, after=1.0, *, agents=True):
        super().__init__()
        a = finite_array(after, "Step", "after")
        b = finite_array(before, "Step", "before")
        b = np.broadcast_to(b, a.shape).copy()
        self.declare_parameter("time", finite_array(time, "Step", "time", ()), unit="s")
        self.declare_parameter("before", b)
        self.declare_parameter("after", a)
        self.declare_output("y", a.shape, agents=agents and a.ndim > 0)

    def output(self, t, x, u, xp):
        return {"y": xp.where(t >= self.time, xp.asarray(self.after),
                              xp.asarray(self.before))}

    def switch_times(self):
        """Times where the output jumps: fixed-step solvers split the major
        step there (RK4 keeps its fourth order across the step). Scalars,
        traced values under the compiled backend."""
        return (self.time,)


class Sine(Block):
    """A sine wave: ``y = amplitude * sin(2 pi frequency t + phase) + bias``.

    Ports
    -----
    y : out, broadcast shape of the parameters

    Parameters
    ----------
    amplitude, frequency (Hz), phase (rad), bias : array_like
        Broadcast against each other (per agent, per component); numeric
        parameters of the broadcast shape.
    agents : bool
        Whether the first axis counts agents.
    """

    def __init__(self, amplitude=1.0, frequency=1.0, phase=0.0, bias=0.0, *,
                 agents=True):
        super().__init__()
        arrs = np.broadcast_arrays(*(finite_array(v, "Sine", n) for v, n in
                                     ((amplitude, "amplitude"), (frequency, "frequency"),
                                      (phase, "phase"), (bias, "bias"))))
        for nm, a in zip(("amplitude", "frequency", "phase", "bias"), arrs, strict=True):
            self.declare_parameter(nm, a, unit={"frequency": "Hz", "phase": "rad"}.get(nm, ""))
        self.declare_output("y", arrs[0].shape, agents=agents and arrs[0].ndim > 0)

    def output(self, t, x, u, xp):
        return {"y": self.amplitude * xp.sin(2 * np.pi * self.frequency * t + self.phase)
                + self.bias}


__all__ = ["Constant", "Clock", "Step", "Sine"]
