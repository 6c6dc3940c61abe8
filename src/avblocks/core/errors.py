"""One error hierarchy for avblocks.

Every error a user can trigger derives from :class:`AvError` and carries
structured context (block, port, expected, found) so the message can name
exactly what is wrong and where.
"""

from __future__ import annotations


class AvError(Exception):
    """Base class of every avblocks error.

    Parameters
    ----------
    cause : str
        What went wrong, in words.
    block, port, param : str, optional
        Where it went wrong.
    expected, found : object, optional
        What was expected and what was found instead.
    hint : str, optional
        How to fix it.
    """

    def __init__(self, cause, *, block=None, port=None, param=None,
                 expected=None, found=None, hint=None):
        self.cause = cause
        self.block = block
        self.port = port
        self.param = param
        self.expected = expected
        self.found = found
        self.hint = hint
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.block is not None:
            where.append(f"block '{self.block}'")
        if self.port is not None:
            where.append(f"port '{self.port}'")
        if self.param is not None:
            where.append(f"parameter '{self.param}'")
        msg = ("in " + ", ".join(where) + ": " if where else "") + self.cause
        parts = []
        if self.expected is not None:
            parts.append(f"expected {self.expected}")
        if self.found is not None:
            parts.append(f"found {self.found}")
        if parts:
            msg += " (" + ", ".join(parts) + ")"
        if self.hint:
            msg += f". {self.hint}"
        return msg


class ParameterError(AvError, ValueError):
    """A block parameter has the wrong type, shape or value."""


class ParameterTypeError(ParameterError, TypeError):
    """A constructor argument of the wrong kind (also a ``TypeError``)."""


class WiringError(AvError):
    """A connection is impossible: unknown port, two drivers, unconnected input."""


class ShapeError(WiringError):
    """Two connected ports disagree on shape, dtype or agent count."""


class AlgebraicLoopError(WiringError):
    """A cycle of direct-feedthrough connections with no state on it."""

    def __init__(self, cycle):
        self.cycle = list(cycle)
        path = ", ".join(self.cycle)
        super().__init__(
            f"algebraic loop (direct-feedthrough wires with no state): {path}",
            hint="break the cycle with a block that has state (Integrator, "
                 "UnitDelay, a vehicle model) or declare the input as not "
                 "direct-feedthrough")


class SimulationError(AvError):
    """A run failed: non-finite values, a block raised, a solver failed.

    ``results`` holds what was logged before the failure.
    """

    def __init__(self, cause, *, results=None, time=None, **kw):
        self.results = results
        self.time = time
        if time is not None:
            cause = f"at t={time:.6g}: {cause}"
        super().__init__(cause, **kw)


class ScenarioError(AvError):
    """A scenario file is malformed; names the file and the entry."""

    def __init__(self, cause, *, file=None, entry=None, hint=None):
        self.file = file
        self.entry = entry
        where = ""
        if file is not None:
            where += f"{file}"
        if entry is not None:
            where += (": " if where else "") + f"{entry}"
        super().__init__((where + ": " if where else "") + cause, hint=hint)


class SimulationWarning(UserWarning):
    """Something went wrong that did not cost the results (a block's
    ``on_stop`` failed after a complete run, for example)."""


class PortAttributeError(WiringError, AttributeError):
    """A port was looked up on a block object instead of its diagram handle."""


class OutputShapeError(SimulationError, ShapeError):
    """A block returned an output of another shape than its port declares,
    during a run (both a :class:`SimulationError` and a :class:`ShapeError`)."""


class CompileError(AvError):
    """A diagram cannot be compiled (a block that cannot be traced by JAX, a
    side-effect block, a variable-step solver): names the block and the fix."""


def did_you_mean(name, options) -> str:
    """``"did you mean 'x'? "`` for the closest of ``options`` to ``name``
    (an empty string when none is close)."""
    import difflib
    close = difflib.get_close_matches(str(name), [str(o) for o in options], n=1,
                                      cutoff=0.6)
    return f"did you mean '{close[0]}'? " if close else ""
