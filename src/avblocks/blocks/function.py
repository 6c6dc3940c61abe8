"""A function block: quick custom logic from a plain Python function."""

from __future__ import annotations

import inspect

import numpy as np

from ..core.block import Block
from ..core.errors import OutputShapeError, ParameterError, ShapeError, SimulationError
from ..core.ports import Port
from ._shapes import set_discrete_state, set_output

_RESERVED = {"t", "xp"}


def _spec(name, value, kind):
    """A Port from ``None`` (inherit), a shape tuple, or a :class:`Port`."""
    if not (isinstance(name, str) and name.isidentifier()) or name in _RESERVED:
        raise ParameterError(f"{kind} names must be identifiers other than 't' and 'xp'",
                             block="Function", param=f"{kind}s", found=repr(name))
    if value is None:
        return Port(name)
    if isinstance(value, Port):
        return Port(name, value.shape, value.dtype, value.unit, value.labels,
                    value.doc, value.agents)
    try:
        shape = tuple(int(s) for s in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{kind} '{name}' needs a shape tuple, a Port or None",
                             block="Function", param=f"{kind}s",
                             found=repr(value)[:80]) from None
    if any(s < 0 for s in shape):
        raise ParameterError(f"{kind} '{name}' has a negative size", block="Function",
                             param=f"{kind}s", found=shape)
    return Port(name, shape)


class Function(Block):
    """Wrap ``fn(t, **inputs) -> outputs`` as a block.

    Ports
    -----
    one input per entry of ``inputs``, one output per entry of ``outputs``.

    State
    -----
    One discrete state per output (its last value) when ``feedthrough`` is
    false; none otherwise.

    Parameters
    ----------
    fn : callable
        ``fn(t, **inputs)`` returning a dict ``{output: array}``, or a bare
        array when there is a single output. When its signature has an ``xp``
        parameter it also receives the array namespace (``xp=numpy`` or
        ``jax.numpy``): write the math with it to run under a compiled
        backend. ``fn`` must be pure (no writes into its arguments).
    inputs : dict of str -> shape tuple, :class:`~avblocks.Port` or None
        Input ports (``None``: take the shape of what is wired to it).
    outputs : dict of str -> shape tuple, :class:`~avblocks.Port` or None
        Output ports (``None``: inferred when the diagram is built by calling
        ``fn`` once on zero inputs at t = 0).
    feedthrough : bool
        True (default): outputs are ``fn`` of the inputs at the same instant.
        False: outputs are ``fn`` of the inputs at the previous sample (one
        sample delay, which breaks algebraic loops); ``initial`` gives the
        outputs before the first sample (default zeros).
    period, offset : float, optional
        Evaluate periodically and hold the outputs in between (a sampled
        controller). Default: continuous (every solver stage with feedthrough,
        every major step without).
    initial : dict of str -> array_like, optional
        Initial outputs when ``feedthrough`` is false.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> f = Function(lambda t, x, xp: -x, inputs={"x": (2,)}, outputs={"dx": (2,)})
    >>> f.output(0.0, {}, {"x": np.array([1.0, 2.0])}, np)["dx"]
    array([-1., -2.])
    """

    def __init__(self, fn, inputs=None, outputs=None, *, feedthrough=True,
                 period=None, offset=0.0, initial=None):
        super().__init__()
        if not callable(fn):
            raise ParameterError("fn must be callable", block="Function", param="fn",
                                 found=type(fn).__name__)
        inputs = {} if inputs is None else inputs
        if not isinstance(inputs, dict) or not isinstance(outputs, dict) or not outputs:
            raise ParameterError("inputs and outputs must be dicts {name: shape}, with at "
                                 "least one output", block="Function", param="outputs",
                                 found=f"inputs={inputs!r}, outputs={outputs!r}"[:120])
        if not isinstance(feedthrough, (bool, np.bool_)):
            raise ParameterError("feedthrough must be True or False", block="Function",
                                 param="feedthrough", found=repr(feedthrough))
        self.fn = fn
        self.feedthrough_ = bool(feedthrough)
        try:
            sig = inspect.signature(fn)
        except (TypeError, ValueError):
            sig = None
        self._pass_xp = sig is not None and "xp" in sig.parameters
        if sig is not None:
            probe = {k: None for k in inputs}
            if self._pass_xp:
                probe["xp"] = np
            try:
                sig.bind(0.0, **probe)
            except TypeError as e:
                raise ParameterError(
                    f"fn cannot be called as fn(t, {', '.join(inputs)}): {e}",
                    block="Function", param="fn",
                    hint="name fn's parameters after the input ports") from None
        for nm, v in inputs.items():
            p = _spec(nm, v, "input")
            self.declare_input(nm, p.shape, p.dtype, unit=p.unit, labels=p.labels,
                               doc=p.doc, agents=p.agents, feedthrough=self.feedthrough_)
        for nm, v in outputs.items():
            if nm in inputs:
                raise ParameterError("a name is both an input and an output",
                                     block="Function", param="outputs", found=nm)
            p = _spec(nm, v, "output")
            self.declare_output(nm, p.shape, p.dtype, unit=p.unit, labels=p.labels,
                                doc=p.doc, agents=p.agents)
        self._out_names = tuple(outputs)
        self._in_names = tuple(inputs)
        init = {} if initial is None else dict(initial)
        if init and self.feedthrough_:
            raise ParameterError("initial outputs only apply with feedthrough=False",
                                 block="Function", param="initial")
        unknown = set(init) - set(outputs)
        if unknown:
            raise ParameterError("initial names unknown outputs", block="Function",
                                 param="initial", expected=sorted(outputs),
                                 found=sorted(unknown))
        self._initial = {k: np.asarray(v) for k, v in init.items()}
        if period is not None:
            self.declare_periodic(period, offset)
        if not self.feedthrough_:
            for nm, p in self._outputs.items():
                if p.shape is not None:
                    self._declare_memory(nm, p)

    def _declare_memory(self, nm, p):
        v = self._initial.get(nm, np.zeros((), dtype=p.dtype))
        try:
            v = np.broadcast_to(v, p.shape).astype(p.dtype)
        except ValueError:
            raise ShapeError("initial output does not match the port", block="Function",
                             port=nm, expected=p.shape, found=np.shape(v)) from None
        set_discrete_state(self, nm, v, dtype=p.dtype, agents=p.agents)

    def _call(self, t, u, xp):
        kw = {k: u[k] for k in self._in_names}
        if self._pass_xp:
            kw["xp"] = xp
        y = self.fn(t, **kw)
        if not isinstance(y, dict):
            if len(self._out_names) != 1:
                raise SimulationError("fn must return a dict {output: array} when the "
                                      "block has several outputs", block="Function",
                                      expected=list(self._out_names),
                                      found=type(y).__name__)
            y = {self._out_names[0]: y}
        elif set(y) != set(self._out_names):
            raise SimulationError("fn returned other outputs than declared",
                                  block="Function", expected=sorted(self._out_names),
                                  found=sorted(y))
        # every call, not only the first: a (1, 2) result for a (3, 2) port
        # would otherwise be broadcast to every agent downstream (one tuple
        # comparison per output)
        for nm, v in y.items():
            want = self._outputs[nm].shape
            got = getattr(v, "shape", None)
            if got is None:
                got = np.shape(v)
            if want is not None and tuple(got) != want:
                raise OutputShapeError(f"fn returned the wrong shape for output '{nm}'",
                                      port=nm, expected=want, found=tuple(got),
                                      hint="return exactly the declared shape")
        return y

    def configure(self, inputs):
        missing = [nm for nm, p in self._outputs.items() if p.shape is None]
        if missing:
            probe = {k: np.zeros(p.shape, dtype=p.dtype) for k, p in inputs.items()}
            try:
                y = self._call(0.0, probe, np)
            except Exception as e:  # noqa: BLE001 - report in words
                raise ShapeError(f"cannot infer output shapes: fn failed on zero inputs "
                                 f"({type(e).__name__}: {e})", block="Function",
                                 port=missing[0], hint="give the output shapes") from e
            for nm in missing:
                a = np.asarray(y[nm])
                set_output(self, nm, a.shape, a.dtype.name)
        if not self.feedthrough_:
            for nm, p in self._outputs.items():
                self._declare_memory(nm, p)

    def output(self, t, x, u, xp):
        if not self.feedthrough_:
            return {nm: x[nm] for nm in self._out_names}
        return self._call(t, u, xp)

    def update(self, t, x, u, xp):
        return self._call(t, u, xp)
