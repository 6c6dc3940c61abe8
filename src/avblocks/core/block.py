"""The :class:`Block` base class: a declaration plus pure functions.

A block declares, in its constructor, everything the simulator needs to know:
its input and output ports, its continuous and discrete states with their
initial values, its sample time and which inputs feed directly through to its
outputs. It then computes only from values the simulator hands it:

``output(t, x, u, xp) -> {output_name: array}``
    outputs from time ``t``, state dict ``x`` (continuous and discrete states
    by name) and input dict ``u``.
``derivative(t, x, u, xp) -> {continuous_state_name: array}``
    time derivative of each continuous state.
``update(t, x, u, xp) -> {discrete_state_name: array}``
    next value of each discrete state, at the block's sample hits.

``xp`` is the array namespace (``numpy`` by default, ``jax.numpy`` when a
diagram is traced). The functions never write into ``x`` or ``u``; they draw
randomness only from random-key states (see :mod:`avblocks.core.rng`).

Example
-------
A proportional heading controller in a few lines:

>>> import numpy as np, avblocks as av
>>> class HeadingP(av.Block):
...     def __init__(self, n, gain=1.0, heading=0.0):
...         super().__init__()
...         self.gain, self.heading = gain, heading
...         self.declare_input("pose", (n, 3))
...         self.declare_output("cmd", (n, 2))
...     def output(self, t, x, u, xp):
...         err = av.utility.wrap_angle(self.heading - u["pose"][:, 2], xp)
...         return {"cmd": xp.stack([xp.ones_like(err), self.gain * err], axis=-1)}
>>> b = HeadingP(2)
>>> b.output(0.0, {}, {"pose": np.zeros((2, 3))}, np)["cmd"].shape
(2, 2)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .errors import ParameterError
from .guarded import _guard_init
from .params import Param, frozen, integer
from .ports import Port
from .sample_times import CONTINUOUS, INHERITED, Continuous, Inherited, Periodic  # noqa: F401


def _check_arguments(cls, arguments):
    """What every block's constructor arguments must be, checked before it
    runs (:func:`~avblocks.core.guarded._guard_init`): ``n`` is the number of
    agents, a whole number >= 1 (so ``n = -3`` is reported on ``n``, not on an
    array it would have sized; declared so by
    :func:`~avblocks.core.declarations.constructor_parameters`)."""
    n = arguments.get("n")
    if n is not None:
        integer(n, cls.__name__, "n", lo=1)

class Block:
    """Base class of every block. See the module docstring for the contract.

    Subclasses call ``super().__init__()`` and then the ``declare_*`` methods.
    Set ``self.n`` to the number of agents when the block has an agent axis.
    """

    #: True when ``on_major_step`` has side effects (I/O, drawing, hardware).
    side_effects = False

    #: False for a block whose math is NumPy/SciPy/shapely code that JAX cannot
    #: trace (spatial indexes, geometry): ``backend="jax"`` then refuses the
    #: diagram at compile time naming the block. Blocks written with ``xp``
    #: only keep the default.
    traceable = True

    #: True when ``update`` needs this block's own outputs of the same major
    #: step (Simulink's and Drake's discrete updates may read them too). The
    #: simulator then calls ``update(t, x, u, xp, y=outputs)``, so work done in
    #: ``output`` (a distance, a mode test) is not repeated in ``update``.
    update_uses_outputs = False

    #: Constructor arguments that build a small working instance, written as
    #: a scenario file writes them (``"$agents"``, ``"$seed"``, generators):
    #: what the editor's palette starts a dragged block with. None: derived
    #: from the required arguments (``n`` is ``$agents``; poses, positions
    #: and waypoints are random ones).
    example = None

    #: What the signature and docstring cannot say about a constructor
    #: argument: ``{name: {"kind": ..., "bounds": [lo, hi], "unit": ...,
    #: "choices": [...]}}`` (see :class:`avblocks.core.declarations.ParameterDecl`).
    parameter_info: dict = {}

    @classmethod
    def constructor_parameters(cls) -> list:
        """The constructor's arguments as declarations (kind, shape, default,
        bounds, unit, description): :func:`avblocks.core.declarations.constructor_parameters`."""
        from .declarations import constructor_parameters
        return constructor_parameters(cls)

    def port_table(self, n=None, *, symbolic=True) -> dict:
        """This instance's ports with the agent axis as ``N`` (the block's
        ``n``, else ``n``; ``symbolic=False``: every size as a number):
        :func:`avblocks.core.declarations.port_table`."""
        from .declarations import port_table
        return port_table(self, n, symbolic=symbolic)

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if "__init__" in cls.__dict__ and not getattr(cls.__init__, "_av_guarded", False):
            cls.__init__ = _guard_init(cls, cls.__dict__["__init__"], _check_arguments)

    def __getattr__(self, name):
        # only reached when normal lookup fails: a port name gets a clear hint
        if not name.startswith("_"):
            d = self.__dict__
            if name in d.get("_inputs", ()) or name in d.get("_outputs", ()):
                from .errors import PortAttributeError
                raise PortAttributeError(
                    "ports are reached through the handle Diagram.add returned, "
                    "not through the block object", port=name,
                    hint=f"h = diagram.add(block); then h.{name}")
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    def __init__(self):
        self._inputs: dict[str, Port] = {}
        self._outputs: dict[str, Port] = {}
        self._feedthrough: set[str] = set()
        self._cstates: dict[str, Port] = {}
        self._dstates: dict[str, Port] = {}
        self._init: dict[str, np.ndarray] = {}
        self._random: set[str] = set()
        self._inherited: set[str] = set()
        self._params: dict[str, Param] = {}
        self.sample_time = CONTINUOUS

    # ------------------------------------------------------------------ declare
    def _check_new(self, name, state=False):
        if not hasattr(self, "_inputs"):
            raise ParameterError(
                f"{type(self).__name__}.__init__ must call super().__init__() "
                "before declaring ports or states")
        if state and (name in self._cstates or name in self._dstates):
            raise ParameterError("state declared twice", block=type(self).__name__,
                                 param=name)

    def declare_input(self, name, shape=None, dtype="float64", *, unit="",
                      labels=(), doc="", agents=True, feedthrough=True) -> Port:
        """Declare an input port.

        ``feedthrough=False`` promises that the outputs do not depend on this
        input at the same instant (only through state); the diagram uses it
        to order blocks and to detect algebraic loops.
        """
        self._check_new(name)
        if name in self._inputs:
            raise ParameterError("input declared twice", block=type(self).__name__,
                                 port=name)
        p = Port(name, shape, dtype, unit, tuple(labels), doc, agents)
        self._inputs[name] = p
        if shape is None:
            self._inherited.add(name)
        if feedthrough:
            self._feedthrough.add(name)
        else:
            self._feedthrough.discard(name)
        return p

    def declare_output(self, name, shape=None, dtype="float64", *, unit="",
                       labels=(), doc="", agents=True) -> Port:
        """Declare an output port."""
        self._check_new(name)
        if name in self._outputs:
            raise ParameterError("output declared twice", block=type(self).__name__,
                                 port=name)
        p = Port(name, shape, dtype, unit, tuple(labels), doc, agents)
        self._outputs[name] = p
        return p

    def declare_continuous_state(self, name, value, *, unit="", labels=(),
                                 doc="", agents=True) -> Port:
        """Declare a continuous state with its initial value (float array)."""
        self._check_new(name, state=True)
        v = np.array(value, dtype=float, order="C")
        p = Port(name, v.shape, "float64", unit, tuple(labels), doc, agents)
        self._cstates[name] = p
        self._init[name] = frozen(v)
        return p

    def declare_discrete_state(self, name, value, *, dtype=None, unit="",
                               labels=(), doc="", agents=True) -> Port:
        """Declare a discrete state with its initial value."""
        self._check_new(name, state=True)
        v = np.array(value, dtype=dtype, order="C")
        p = Port(name, v.shape, v.dtype.name, unit, tuple(labels), doc, agents)
        self._dstates[name] = p
        self._init[name] = frozen(v)
        return p

    def declare_random_state(self, name="key") -> Port:
        """Declare a random-generator key, seeded by the simulator.

        Draw with :mod:`avblocks.core.rng` in ``update`` and return the next
        key. Each block gets its own stream from the run's seed and the
        block's name, so runs are repeatable.
        """
        from . import rng as _rng
        p = self.declare_discrete_state(name, _rng.key(0), agents=False)
        self._random.add(name)
        return p

    def declare_parameter(self, name, value, shape=None, *, bounds=(None, None),
                          unit="", doc="", allow_inf=False) -> np.ndarray:
        """Declare a numeric parameter and set ``self.<name>`` to its value.

        ``value`` is validated into a float64 array of ``shape`` (default:
        the value's own shape; a scalar is broadcast to ``shape``), finite
        (``allow_inf`` for one-sided limits) and within ``bounds``
        (inclusive, ``None`` = open). The block must read it only as
        ``self.<name>`` inside its pure functions: it can then be changed
        between runs or during a run (:meth:`set_parameter`,
        ``Simulator.set_param("block.name", v)``), swept, vmapped and
        differentiated by the compiled backend without a rebuild.
        """
        self._check_new(name)
        if name in self._params:
            raise ParameterError("parameter declared twice", block=type(self).__name__,
                                 param=name)
        if shape is None:
            shape = np.shape(value)
        spec = Param(name, shape, bounds, unit, doc, allow_inf)
        a = spec.validate(value, type(self).__name__)
        self._params[name] = spec
        self.__dict__[name] = a
        return a

    def param_flag(self, key, xp, test, *names) -> bool:
        """A Python bool ``test(*values)`` of the current values of the named
        parameters, for skipping work that a value makes a no-op (a clip
        to an infinite limit, a zero drag term) on the NumPy path.

        Cached until one of the parameters is given a new value (every set
        replaces the array). Under any other array namespace (a traced
        JAX value) it is ``True``: the general computation is done.
        """
        if xp is not np:
            return True
        d = self.__dict__
        cache = d.get("_flag_cache")
        if cache is None:
            cache = d["_flag_cache"] = {}
        hit = cache.get(key)
        if hit is not None:
            for a, n in zip(hit[0], names):
                if a is not d[n]:
                    break
            else:
                return hit[1]
        vals = tuple(d[n] for n in names)
        r = bool(test(*vals))
        cache[key] = (vals, r)
        return r

    @property
    def parameters(self) -> dict[str, Param]:
        """The declared numeric parameters by name."""
        return dict(self._params)

    def _param_spec(self, name, block=None):
        try:
            return self._params[name]
        except KeyError:
            import difflib
            close = difflib.get_close_matches(str(name), list(self._params), n=1)
            raise ParameterError("no such numeric parameter",
                                 block=block or type(self).__name__, param=name,
                                 expected=f"one of {sorted(self._params)}",
                                 found=name,
                                 hint=f"did you mean '{close[0]}'?" if close else None
                                 ) from None

    def get_parameter(self, name) -> np.ndarray:
        """Current value of a numeric parameter (a copy)."""
        self._param_spec(name)
        return np.array(self.__dict__[name], dtype=float)

    def set_parameter(self, name, value, *, block=None):
        """Validate and set a numeric parameter (same shape, within bounds)."""
        spec = self._param_spec(name, block)
        self.__dict__[name] = spec.validate(value, block or type(self).__name__)

    def parameter_values(self) -> dict[str, np.ndarray]:
        """``{name: value}`` of every numeric parameter."""
        return {k: self.__dict__[k] for k in self._params}

    def declare_periodic(self, period, offset=0.0):
        """Make the block discrete with sample hits at ``offset + k*period``."""
        self.sample_time = Periodic(float(period), float(offset))

    def declare_inherited(self):
        """Take the sample time of the driving blocks (see :class:`Inherited`)."""
        self.sample_time = INHERITED

    # ------------------------------------------------------------ introspection
    @property
    def input_ports(self) -> dict[str, Port]:
        return dict(self._inputs)

    @property
    def output_ports(self) -> dict[str, Port]:
        return dict(self._outputs)

    @property
    def continuous_states(self) -> dict[str, Port]:
        return dict(self._cstates)

    @property
    def discrete_states(self) -> dict[str, Port]:
        return dict(self._dstates)

    @property
    def random_states(self) -> set[str]:
        return set(self._random)

    @property
    def feedthrough(self) -> set[str]:
        """Names of inputs that feed directly through to the outputs."""
        return set(self._feedthrough)

    def initial_state(self) -> dict[str, np.ndarray]:
        """Initial values of all states by name (copies)."""
        return {k: v.copy() for k, v in self._init.items()}

    def set_initial(self, name, value):
        """Replace the initial value of a declared state (same shape)."""
        if name not in self._init:
            raise ParameterError("no such state", block=type(self).__name__,
                                 param=name, expected=sorted(self._init), found=name)
        old = self._init[name]
        v = np.array(value, dtype=old.dtype, order="C")
        if v.shape != old.shape:
            raise ParameterError("initial value has the wrong shape",
                                 block=type(self).__name__, param=name,
                                 expected=old.shape, found=v.shape)
        self._init[name] = frozen(v)

    @property
    def has_derivative(self) -> bool:
        return bool(self._cstates)

    @property
    def has_update(self) -> bool:
        return bool(self._dstates)

    # --------------------------------------------------------------- behaviour
    def configure(self, inputs: dict[str, Port]) -> None:
        """Hook for shape-polymorphic blocks, called once when the diagram is
        built, with ``{input name: spec of the output wired to it}`` (the
        spec's ``name`` is the source port's). Re-declare outputs/states here
        (``redeclare_output``, ``redeclare_state``). Default: nothing.
        """

    def redeclare_output(self, name, shape, dtype=None, *, agents=None):
        """Fix the shape (and dtype, agent flag) of an output, in ``configure``."""
        p = self._outputs[name].with_shape(shape, dtype)
        if agents is not None:
            p = replace(p, agents=bool(agents))
        self._outputs[name] = p

    def redeclare_input(self, name, shape, dtype=None):
        self._inputs[name] = self._inputs[name].with_shape(shape, dtype)

    def redeclare_state(self, name, value, *, dtype=None):
        """Replace a declared state's initial value, shape and dtype (for
        shape-polymorphic blocks, in ``configure``)."""
        if name in self._cstates:
            v = np.array(value, dtype=float, order="C")
            self._cstates[name] = replace(self._cstates[name], shape=v.shape)
        elif name in self._dstates:
            v = np.array(value, dtype=dtype, order="C")
            self._dstates[name] = replace(self._dstates[name], shape=v.shape,
                                          dtype=v.dtype.name)
        else:
            raise ParameterError("no such state", block=type(self).__name__, param=name)
        self._init[name] = frozen(v)

    def output(self, t, x, u, xp):
        """Outputs at time ``t`` (dict by output name). Default: none."""
        return {}

    def derivative(self, t, x, u, xp):
        """Derivatives of the continuous states (dict by state name)."""
        raise NotImplementedError(
            f"{type(self).__name__} declares continuous states but no derivative()")

    def update(self, t, x, u, xp):
        """Next values of the discrete states (dict by state name).

        With ``update_uses_outputs = True`` the signature is
        ``update(t, x, u, xp, y)``: ``y`` holds the block's outputs at ``t``.
        """
        raise NotImplementedError(
            f"{type(self).__name__} declares discrete states but no update()")

    def on_major_step(self, t, x, u, y):
        """Side effects at a major step (drawing, I/O). Only called when the
        class sets ``side_effects = True``; never inside solver stages."""

    def on_start(self):
        """Called once before a run (open windows, connections)."""

    def on_stop(self):
        """Called once after a run, also when it failed (close resources)."""

    def __repr__(self):
        def short(ports):
            return ", ".join(f"{k} {_shape_text(p)}" for k, p in ports.items())
        return (f"{type(self).__name__}(in: [{short(self._inputs)}], "
                f"out: [{short(self._outputs)}])")

    def __str__(self):
        """A table of the block's ports, states and parameters."""
        rows = []
        for kind, ports in (("in", self._inputs), ("out", self._outputs),
                            ("state", {**self._cstates, **self._dstates})):
            for k, p in ports.items():
                extra = " ".join(x for x in (
                    p.dtype if p.dtype != "float64" else "",
                    f"[{p.unit}]" if p.unit else "",
                    f"({', '.join(p.labels)})" if p.labels else "") if x)
                rows.append((kind, k, _shape_text(p), extra))
        for k, prm in self._params.items():
            v = np.asarray(self.__dict__.get(k, np.nan))
            val = f"{v.item():g}" if v.size == 1 else f"array{v.shape}"
            unit = getattr(prm, "unit", "") or ""
            rows.append(("param", k, val, f"[{unit}]" if unit else ""))
        if not rows:
            return repr(self)
        w1 = max(len(r[1]) for r in rows)
        w2 = max(len(r[2]) for r in rows)
        st = self.sample_time
        rate = ("continuous" if isinstance(st, Continuous) else
                f"every {st.period:g} s" + (f" from {st.offset:g} s" if st.offset else "")
                if isinstance(st, Periodic) else "rate of its inputs")
        lines = [f"{type(self).__name__} ({rate})"]
        lines += [f"  {a:<6}{b:<{w1}}  {c:<{w2}}  {d}".rstrip() for a, b, c, d in rows]
        return "\n".join(lines)


def _shape_text(p) -> str:
    """``(N, 3)``-style shape text (``(any)`` for inherited shapes)."""
    if p.shape is None:
        return "(any)"
    return "(" + ", ".join(str(s) for s in p.shape) + ("," if len(p.shape) == 1 else "") + ")"
