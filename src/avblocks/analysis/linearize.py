r"""Linear state-space models of a diagram at an operating point.

:func:`linearize` turns a diagram and an operating point into
``(A, B, C, D)`` with every state, input and output named by block, port,
agent and component (:mod:`avblocks.analysis.names`). The Jacobians are
exact: ``jax.jacfwd`` of the functions the compiled engine traces for a run
(:class:`~avblocks.core.compiled.engine.TracedEngine`: the blocks' outputs
in evaluation order, their derivatives, discrete updates and the solver's
step), not a second implementation of the diagram's semantics.

Continuous-time model
---------------------
For a diagram whose states are all continuous (no periodic block, no
floating-point discrete state), the model is

.. math::

    \dot x = f(t, x, u),\quad y = g(t, x, u),\qquad
    A = \partial f/\partial x,\ B = \partial f/\partial u,\
    C = \partial g/\partial x,\ D = \partial g/\partial u

at ``(t, x_0, u_0)``, where ``x`` stacks every continuous state of the
diagram (blocks in evaluation order, each block's states in the order it
declared them, each array flattened in C order), ``u`` the perturbations at
the chosen input ports and ``y`` the chosen output ports. ``f(t, x_0, u_0)``
is kept as :attr:`LinearModel.f0`: zero at an equilibrium, the velocity of
the operating point otherwise (a formation moving at constant speed).

Input perturbations
-------------------
Every input port of a diagram is wired. Naming one in ``inputs`` makes the
value that port reads the wired signal *plus* a perturbation ``u`` (of the
port's shape, nominal value 0 or the value given in ``at``); no other
reader of the same signal sees it. ``B`` and ``D`` are the responses to
that perturbation, so a loop closed through the port stays closed: this is
the closed-loop model seen from an injection point, as Simulink's input
perturbation points and Drake's ``Linearize`` of a diagram's input port.

Discrete and mixed diagrams: the sampled model
----------------------------------------------
When the diagram has periodic blocks or floating-point discrete states,
the model is the discrete-time map of one base period ``T`` of the
simulator itself:

.. math::

    x[k+1] = \Phi(x[k], u[k]),\quad y[k] = g(t_k, x[k], u[k]),\qquad
    A = \partial\Phi/\partial x,\ \dots

with ``x`` the continuous states followed, block by block, by the
floating-point discrete states, ``T`` the least common multiple of the
periodic blocks' periods (a whole number ``m`` of major steps ``dt``; ``T =
dt`` when only blocks updated every major step are discrete) and ``u`` held
over the period (zero-order hold). ``\Phi`` is ``m`` major steps of the
engine exactly as a run takes them (outputs, discrete updates at their
hits, the fixed-step solver's stages for the continuous states), starting
at a step where every periodic block has a hit; ``y`` is what a run logs at
that step. So the model is the linearisation of what the simulator
computes, the solver's discretisation included (RK4's error in ``\Phi``
is ``O(dt^5)`` per step). Periodic blocks with a non-zero offset are
refused: their held outputs would be states of the map.

Why this choice: the alternative (a continuous model with discrete blocks
converted by ``d2c``, as Simulink's default) invents dynamics the run does
not have; the sampled map is the one the run has, and a purely continuous
part can still be asked for with ``kind="continuous"`` (discrete states
are then frozen at their values in ``at`` and periodic blocks are taken as
transparent: they compute their outputs from the current signals).

Integer and boolean discrete states (modes, counters, random keys) never
enter ``x``: they are held at their operating values.

References
----------
The MathWorks, Simulink Control Design: "Linearize Nonlinear Models" and
``linmod``; R. Tedrake, Drake ``systems/primitives/linear_system.h``
(``Linearize``); G. F. Franklin, J. D. Powell, M. Workman, *Digital
Control of Dynamic Systems* (3rd ed., 1998), ch. 4 (sampled models).
"""

from __future__ import annotations

import difflib
import math
import threading
from fractions import Fraction

import numpy as np

from ..core.block import Block as _Block
from ..core.block import Periodic
from ..core.diagram import CompiledDiagram, Diagram, PortRef
from ..core.errors import AvError, CompileError, ParameterError, WiringError
from .model import LinearModel
from .names import entry_names

_KINDS = ("auto", "continuous", "sampled")
#: one trace at a time: a trace binds traced parameter values to the blocks
_LOCK = threading.RLock()


def _jax():
    """The ``jax`` module (the ``jax`` extra), or an AvError saying so."""
    from ..core.compiled import require_jax
    return require_jax()


def _x64(jax):
    """Scoped 64-bit types (the models are always float64)."""
    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(True)
    from jax import experimental
    return experimental.enable_x64()


# ---------------------------------------------------------------- resolving names
def _as_list(v, what):
    if v is None:
        return []
    if isinstance(v, (str, PortRef)):
        return [v]
    try:
        return list(v)
    except TypeError:
        raise ParameterError(f"{what} must be a list of 'block.port' names",
                             param=what, found=type(v).__name__) from None


def _path_of(ref):
    return ref.path if isinstance(ref, PortRef) else str(ref)


def _all_inputs(cd):
    return [f"{n}.{p}" for n, b in zip(cd.names, cd.blocks) for p in b.input_ports]


def _all_outputs(cd):
    return [f"{n}.{p}" for n, b in zip(cd.names, cd.blocks) for p in b.output_ports]


def _handle(diagram, path):
    """The block handle at the dotted ``path`` (through subsystems), or None."""
    cur, handle = diagram, None
    for part in path.split(".") if path else ():
        if not isinstance(cur, Diagram) or part not in cur.blocks:
            return None
        handle = cur[part]
        cur = handle.block
    return handle


def _leaf_inputs(cd, ref):
    """``[(block index, input name)]`` the input port ``ref`` reaches (a leaf
    block's input, or a subsystem's exported input: every leaf it feeds)."""
    path = _path_of(ref)
    bpath, _, name = path.rpartition(".")
    handle = ref.handle if isinstance(ref, PortRef) else _handle(cd.diagram, bpath)
    if handle is None:
        close = difflib.get_close_matches(path, _all_inputs(cd), n=3)
        raise WiringError("no such block for a linear model input", found=path,
                          expected="'<block path>.<input port>'",
                          hint=(f"did you mean {close}?" if close else
                                f"input ports: {_all_inputs(cd)[:20]}"))
    blk = handle.block
    if isinstance(blk, Diagram):
        if name not in blk._ex_in:
            raise WiringError("not an exported input of the subsystem", block=bpath,
                              port=name, expected=sorted(blk._ex_in), found=name)
        out = []
        for dst in blk._ex_in[name]:
            out += _leaf_inputs(cd, dst)
        return out
    i = cd.index(handle.path)
    if name not in blk.input_ports:
        if name in blk.output_ports:
            readers = [f"{cd.names[j]}.{inp}" for j, srcs in enumerate(cd.sources)
                       for inp, (s, o) in srcs.items() if s == i and o == name]
            raise WiringError("an output port cannot be a linear model input: name the "
                              "input port where the perturbation enters", block=bpath,
                              port=name, expected=f"one of its readers {readers}",
                              found=f"output {name}")
        raise WiringError("no such input port", block=bpath, port=name,
                          expected=f"one of {sorted(blk.input_ports)}", found=name)
    return [(i, name)]


def _resolve_outputs(cd, refs):
    out = []
    for r in refs:
        path = _path_of(r)
        try:
            i, o = cd.resolve(r)
        except WiringError as e:
            close = difflib.get_close_matches(path, _all_outputs(cd), n=3)
            raise WiringError(f"unknown linear model output '{path}': {e.cause}",
                              block=e.block, port=e.port, expected=e.expected,
                              found=e.found,
                              hint=f"did you mean {close}?" if close else None) from None
        spec = cd.blocks[i].output_ports[o]
        if np.dtype(spec.dtype).kind != "f":
            raise ParameterError("a linear model output must be a floating-point signal",
                                 block=cd.names[i], port=o, found=spec.dtype)
        out.append((path, i, o, spec))
    return out


def _resolve_inputs(cd, refs):
    out = []
    seen = set()
    for r in refs:
        path = _path_of(r)
        leaves = _leaf_inputs(cd, r)
        for i, inp in leaves:
            if (i, inp) in seen:
                raise ParameterError("an input port is named twice", block=cd.names[i],
                                     port=inp, param="inputs")
            seen.add((i, inp))
        spec = cd.blocks[leaves[0][0]].input_ports[leaves[0][1]]
        for i, inp in leaves:
            s = cd.blocks[i].input_ports[inp]
            if np.dtype(s.dtype).kind != "f":
                raise ParameterError("a linear model input must be a floating-point "
                                     "signal", block=cd.names[i], port=inp, found=s.dtype)
            if tuple(s.shape) != tuple(spec.shape):
                raise ParameterError("the subsystem input feeds ports of different "
                                     "shapes", block=cd.names[i], port=inp,
                                     expected=spec.shape, found=s.shape)
        out.append((path, leaves, spec))
    return out


# ---------------------------------------------------------------- time steps
def _fraction(x):
    return Fraction(x).limit_denominator(10**9)


def _gcd_step(values):
    """The largest step that divides every value (floats, as fractions)."""
    g = Fraction(0)
    for v in values:
        f = _fraction(v)
        g = Fraction(math.gcd(g.numerator * f.denominator, f.numerator * g.denominator),
                     g.denominator * f.denominator)
    return float(g)


# ---------------------------------------------------------------- the linearizer
class Linearizer:
    """Linear models of one diagram for many operating points and parameter
    values, traced and compiled once.

    ``Linearizer(diagram, inputs=..., outputs=...)(at=..., params=...)``
    gives a :class:`LinearModel`; a second call with other values (a gain
    sweep for a root locus, another operating point) reuses the compiled
    Jacobian. Arguments as :func:`linearize`.
    """

    def __init__(self, diagram, *, inputs=(), outputs=(), kind="auto", dt=None,
                 solver="rk4", seed=0):
        from ..core.solvers import make_solver
        jax = _jax()
        if isinstance(diagram, Diagram):
            cd = diagram.build()
        elif isinstance(diagram, CompiledDiagram):
            cd = diagram
        else:
            raise ParameterError("linearize needs a Diagram", param="diagram",
                                 expected="Diagram", found=type(diagram).__name__)
        if kind not in _KINDS:
            raise ParameterError("unknown kind of linear model", param="kind",
                                 expected=list(_KINDS), found=kind)
        self.cd = cd
        self.seed = int(seed)
        bad = [n for n, b in zip(cd.names, cd.blocks)
               if b.side_effects or not getattr(b, "traceable", True)]
        if bad:
            raise CompileError("linearize traces the diagram with JAX: this block has "
                               "side effects or runs NumPy-only code", block=bad[0],
                               hint="linearize the diagram with the model block in its "
                                    "place (an interface block has no model to linearize)")
        self.outs = _resolve_outputs(cd, _as_list(outputs, "outputs"))
        self.ins = _resolve_inputs(cd, _as_list(inputs, "inputs"))
        periodic = [b for b in cd.blocks if isinstance(b.sample_time, Periodic)]
        fdisc = [(i, nm) for i, b in enumerate(cd.blocks) for nm, p in b._dstates.items()
                 if nm not in b._random and np.dtype(p.dtype).kind == "f"]
        every_step = [cd.names[i] for i, _ in fdisc
                      if not isinstance(cd.blocks[i].sample_time, Periodic)]
        if kind == "auto":
            kind = "sampled" if (periodic or fdisc) else "continuous"
        self.kind = kind
        # the major step: the caller's, else the largest that divides every
        # period and offset (any positive number for a continuous model)
        times = [v for b in periodic for v in (b.sample_time.period, b.sample_time.offset)
                 if v > 0]
        if dt is None:
            if kind == "sampled" and every_step:
                raise ParameterError(
                    "a sampled model of this diagram needs the major step dt: these blocks "
                    "update a discrete state at every major step", param="dt",
                    found=every_step[:5], hint="pass dt=... (the step of your runs)")
            dt = _gcd_step(times) if times else 1.0
        try:
            dt = float(dt)
        except (TypeError, ValueError):
            dt = float("nan")
        if not (np.isfinite(dt) and dt > 0):
            raise ParameterError("dt must be a positive number", param="dt", found=dt)
        self.dt = dt
        if kind == "sampled":
            offs = [cd.names[i] for i, b in enumerate(cd.blocks)
                    if isinstance(b.sample_time, Periodic) and b.sample_time.offset != 0]
            if offs:
                raise ParameterError(
                    "a sampled model needs periodic blocks without offsets (their held "
                    "outputs would be states of the map)", block=offs[0],
                    param="offset", found=offs,
                    hint="linearize with kind='continuous', or give the blocks offset 0")
            self.solver = make_solver(solver)
            if not self.solver.fixed_step:
                raise ParameterError("a sampled model needs a fixed-step solver",
                                     param="solver", expected="'rk4' or 'euler'",
                                     found=solver)
        else:
            self.solver = None
        # the states of the model, block by block in evaluation order
        slots = []
        off = 0
        for i, b in enumerate(cd.blocks):
            specs = list(b._cstates.items())
            if kind == "sampled":
                specs += [(nm, p) for nm, p in b._dstates.items()
                          if nm not in b._random and np.dtype(p.dtype).kind == "f"]
            for nm, p in specs:
                size = int(np.prod(b._init[nm].shape, dtype=np.int64))
                slots.append((i, nm, tuple(b._init[nm].shape), off, off + size, p))
                off += size
        self.slots = slots
        self.nx = off
        self.state_names = [s for i, nm, _sh, _a, _b, p in slots
                            for s in entry_names(f"{cd.names[i]}.{nm}", _spec(p, _sh))]
        self.state_slots = {f"{cd.names[i]}.{nm}": slice(a, b)
                            for i, nm, _sh, a, b, _p in slots}
        self.in_slices = []
        off = 0
        for _path, _leaves, spec in self.ins:
            size = int(np.prod(spec.shape, dtype=np.int64))
            self.in_slices.append((off, off + size, tuple(spec.shape)))
            off += size
        self.nu = off
        self.input_names = [s for path, _l, spec in self.ins
                            for s in entry_names(path, spec)]
        self.output_names = [s for path, _i, _o, spec in self.outs
                             for s in entry_names(path, spec)]
        if kind == "sampled":
            per = [int(round(b.sample_time.period / dt)) for b in periodic]
            self.steps = math.lcm(*per) if per else 1
        else:
            self.steps = 0
        from . import _engine
        ports = [(i, inp) for _p, leaves, _s in self.ins for i, inp in leaves]
        self._port_of = [j for j, (_p, leaves, _s) in enumerate(self.ins) for _ in leaves]
        with _x64(jax):
            self.eng = _engine.PerturbedEngine(cd, dt, jax.numpy,
                                               jax.dtypes.canonicalize_dtype, ports)
        self._pos = {i: j for j, i in enumerate(self.eng.cont)}
        self._fn = None
        self._jac = None

    # ------------------------------------------------------------ values
    @property
    def period(self) -> float:
        """The sample period of a sampled model (``steps * dt``), 0 if continuous."""
        return self.steps * self.dt if self.kind == "sampled" else 0.0

    def _theta(self, params):
        cd = self.cd
        theta = {f"{n}.{k}": np.asarray(v) for n, b in zip(cd.names, cd.blocks)
                 for k, v in b.parameter_values().items()}
        if params is not None:
            if not isinstance(params, dict):
                raise ParameterError("params must be a dict {'block.name': value}",
                                     param="params", found=type(params).__name__)
            for path, v in params.items():
                i, name = cd.param_index(path)
                spec = cd.blocks[i]._params[name]
                theta[f"{cd.names[i]}.{name}"] = spec.validate(v, cd.names[i])
        return {k: (v.astype(np.float64) if v.dtype.kind == "f" else v)
                for k, v in theta.items()}

    def base_states(self, at=None):
        """The operating point's states, one dict per block (declared
        initial values, then ``at``), and the input perturbations ``u0``."""
        from ..core import rng as _rng
        from ..core.runguard import initial_values
        cd = self.cd
        states, inputs = _split_at(self, at)
        x0vals, _ = initial_values(cd, states)
        X = []
        for j, (name, b) in enumerate(zip(cd.names, cd.blocks)):
            x = dict(b._init) if type(b).initial_state is _Block.initial_state \
                else b.initial_state()
            for (i, nm), v in x0vals.items():
                if i == j:
                    x[nm] = v
            for r in b._random:
                x[r] = _rng.key(self.seed, f"{name}.{r}")
            X.append({k: (np.asarray(v, np.float64) if np.asarray(v).dtype.kind == "f"
                          else np.asarray(v)) for k, v in x.items()})
        u0 = np.zeros(self.nu)
        for j, (path, _l, spec) in enumerate(self.ins):
            if path in inputs:
                v = np.asarray(inputs[path], dtype=float)
                if v.shape != tuple(spec.shape):
                    v = np.broadcast_to(v, spec.shape) if v.ndim == 0 else v
                if v.shape != tuple(spec.shape):
                    raise ParameterError("input perturbation has the wrong shape", param=path,
                                         expected=spec.shape, found=v.shape)
                if not np.all(np.isfinite(v)):
                    raise ParameterError("input perturbation must be finite", param=path)
                a, b, _ = self.in_slices[j]
                u0[a:b] = v.ravel()
        return X, u0

    def pack(self, X) -> np.ndarray:
        """The model's state vector from per-block state dicts."""
        if not self.slots:
            return np.zeros(0)
        return np.concatenate([np.ravel(np.asarray(X[i][nm], dtype=float))
                               for i, nm, *_ in self.slots])

    def unpack(self, x, X=None) -> dict:
        """``{"block.state": array}`` of the state vector ``x``."""
        x = np.asarray(x, dtype=float)
        return {f"{self.cd.names[i]}.{nm}": x[a:b].reshape(sh)
                for i, nm, sh, a, b, _p in self.slots}

    def unpack_inputs(self, u) -> dict:
        """``{"block.port": array}`` of an input perturbation vector ``u``."""
        u = np.asarray(u, dtype=float)
        return {path: u[a:b].reshape(sh)
                for (path, _l, _s), (a, b, sh) in zip(self.ins, self.in_slices)}

    # ------------------------------------------------------------ traced
    def _put(self, Xb, xvec):
        jnp = self.eng.xp
        X = [dict(x) for x in Xb]
        for i, nm, sh, a, b, _p in self.slots:
            X[i][nm] = jnp.reshape(xvec[a:b], sh)
        return X

    def _function(self, xvec, uvec, Xb, theta, t):
        """Traced: ``(f, y)``: the derivative (continuous) or the state after
        one period (sampled) and the outputs, as flat vectors."""
        from ..core import memo as _memo
        from ..core.params import bound_parameters
        eng = self.eng
        jnp = eng.xp
        cd = self.cd
        per_block = {}
        for path, v in theta.items():
            i, k = cd.param_index(path)
            per_block.setdefault(i, (cd.blocks[i], {}))[1][k] = v
        X = self._put(Xb, xvec)
        empty = [dict() for _ in cd.blocks]
        delta = [jnp.reshape(uvec[a:b], sh) for a, b, sh in self.in_slices]
        with bound_parameters(list(per_block.values())), _memo.active(_memo.Memo()):
            eng.delta = [delta[j] for j in self._port_of]
            try:
                Y = eng.all_outputs(t, X, empty)
                y = self._outputs(Y)
                if self.kind == "continuous":
                    K = eng.derivs(t, X, Y)
                    parts = [jnp.ravel(K[self._pos[i]][nm]) for i, nm, *_ in self.slots]
                else:
                    X = self._period(t, X, Y)
                    parts = [jnp.ravel(X[i][nm]) for i, nm, *_ in self.slots]
            finally:
                eng.delta = None
        f = jnp.concatenate(parts) if parts else jnp.zeros(0)
        return f, y

    def _outputs(self, Y):
        jnp = self.eng.xp
        parts = [jnp.ravel(Y[i][o]) for _p, i, o, _s in self.outs]
        return jnp.concatenate(parts) if parts else jnp.zeros(0)

    def _period(self, t, X, Y):
        """``steps`` major steps of the engine from ``(X, Y)`` at a step where
        every periodic block has a hit (see the module docstring)."""
        eng, solver, dt = self.eng, self.solver, self.dt
        X = eng.update(t, X, Y, eng.hits(0))
        X = solver.step(eng, t, X, Y, dt)
        if self.steps == 1:
            return X
        lax = _jax().lax

        def body(carry, k):
            X, Y = carry
            tk = t + k * dt
            h = eng.hits(k)
            Y = eng.major_outputs(tk, X, Y, h)
            X = eng.update(tk, X, Y, h)
            X = solver.step(eng, tk, X, Y, dt)
            return (X, Y), None

        (X, _Y), _ = lax.scan(body, (X, Y), eng.xp.arange(1, self.steps))
        return X

    def _compiled(self):
        if self._fn is None:
            jax = _jax()
            self._fn = jax.jit(self._function)
            self._jac = jax.jit(jax.jacfwd(self._function, argnums=(0, 1)))
        return self._fn, self._jac

    def evaluate(self, x, u, X, theta, t, jacobian=True):
        """``(f, y)`` and, with ``jacobian``, ``((A, B), (C, D))`` at the state
        vector ``x`` and input perturbations ``u`` (float64 NumPy arrays)."""
        fn, jac = self._compiled()
        with _LOCK, _x64(_jax()):
            args = (np.asarray(x, np.float64), np.asarray(u, np.float64), X, theta,
                    np.float64(t))
            f, y = fn(*args)
            out = (np.asarray(f), np.asarray(y))
            if jacobian:
                (A, B), (C, D) = jac(*args)
                out += ((np.asarray(A).reshape(self.nx, self.nx),
                         np.asarray(B).reshape(self.nx, self.nu)),
                        (np.asarray(C).reshape(len(y), self.nx),
                         np.asarray(D).reshape(len(y), self.nu)))
        return out

    def __call__(self, at=None, *, params=None, t=0.0):
        """The :class:`LinearModel` at the operating point ``at`` (see
        :func:`linearize`) with numeric parameters ``params``."""
        t = _time(t)
        X, u0 = self.base_states(at)
        theta = self._theta(params)
        x0 = self.pack(X)
        f, y, (A, B), (C, D) = self.evaluate(x0, u0, X, theta, t)
        for name, m in (("A", A), ("B", B), ("C", C), ("D", D), ("f", f), ("y", y)):
            if not np.all(np.isfinite(m)):
                raise AvError(f"the linearisation is not finite ({name} has NaN or inf) at "
                              "this operating point",
                              hint="a block divides by zero or takes a square root of "
                                   "zero there (e.g. a distance of 0): move the operating "
                                   "point")
        return LinearModel(A, B, C, D, self.period, list(self.state_names),
                           list(self.input_names), list(self.output_names), x0, u0, y,
                           f, t, dict(self.state_slots))


def _spec(port, shape):
    """A state's Port with its actual shape (declared shapes may be resized)."""
    from dataclasses import replace
    return replace(port, shape=shape)


def _time(t):
    try:
        t = float(t)
    except (TypeError, ValueError):
        t = float("nan")
    if not np.isfinite(t):
        raise ParameterError("t must be a finite number", param="t", found=t)
    return t


def _split_at(lin, at):
    """``(states, inputs)`` dicts of an operating point given as a dict
    (state paths and input-port paths), a :class:`TrimResult`, or
    :class:`Results` (their ``final_state``)."""
    from ..core.results import Results
    from .model import TrimResult
    if at is None:
        return {}, {}
    if isinstance(at, TrimResult):
        return dict(at.states), dict(at.inputs)
    if isinstance(at, Results):
        if at.final_state is None:
            raise ParameterError("these results carry no final state", param="at",
                                 hint="pass {'block.state': value} instead")
        if at.runs is not None:
            raise ParameterError("at= takes the results of one run", param="at",
                                 hint="use res.run(r)")
        return {k: v for k, v in at.final_state.items()
                if k.rpartition(".")[2] not in _random_names(lin.cd, k)}, {}
    if not isinstance(at, dict):
        raise ParameterError("at must be a dict {'block.state': value}, a TrimResult or "
                             "Results", param="at", found=type(at).__name__)
    in_paths = {path for path, _l, _s in lin.ins}
    states, inputs = {}, {}
    for k, v in at.items():
        k = _path_of(k)
        if k in in_paths:
            inputs[k] = v
            continue
        bpath, _, nm = k.rpartition(".")
        try:
            i = lin.cd.index(bpath)
        except WiringError:
            i = None
        if i is None or nm not in lin.cd.blocks[i]._init:
            if i is not None and nm in lin.cd.blocks[i].input_ports:
                raise ParameterError("an input's operating value is given for a port that "
                                     "is not among the model's inputs", param=k,
                                     hint="add it to inputs=[...]")
            states_all = [f"{n}.{s}" for n, b in zip(lin.cd.names, lin.cd.blocks)
                          for s in b._init if s not in b._random]
            close = difflib.get_close_matches(k, states_all + sorted(in_paths), n=3)
            raise ParameterError("at names no state and no input of the model", param=k,
                                 expected="'<block>.<state>' or one of inputs",
                                 hint=f"did you mean {close}?" if close else
                                 f"states: {states_all[:20]}")
        states[k] = v
    return states, inputs


def _random_names(cd, path):
    bpath = path.rpartition(".")[0]
    try:
        return cd.blocks[cd.index(bpath)]._random
    except WiringError:
        return set()


# ---------------------------------------------------------------- the function
def linearize(diagram, at=None, *, inputs=(), outputs=(), params=None, t=0.0,
              kind="auto", dt=None, solver="rk4", seed=0) -> LinearModel:
    r"""The linear state-space model of ``diagram`` at an operating point.

    Parameters
    ----------
    diagram : Diagram
        Any diagram the compiled engine can trace (pure ``xp`` blocks, no
        interface blocks).
    at : dict, TrimResult or Results, optional
        The operating point: ``{"block.state": value}`` for states (the
        others keep their initial values) and ``{"block.port": value}`` for
        the perturbation of an input port named in ``inputs`` (default 0); a
        :class:`~avblocks.analysis.TrimResult` (its states and inputs); or
        :class:`~avblocks.Results` (their final state).
    inputs : list of str or ports
        Input ports (``"ctrl.ref"``, a subsystem's exported input) where a
        perturbation ``u`` is added to the wired signal (module docstring).
    outputs : list of str or ports
        Output ports whose values make ``y``.
    params : dict, optional
        Numeric parameter values ``{"block.name": value}`` for this model.
    t : float
        Time of the operating point (time-varying sources) [s].
    kind : ``"auto"``, ``"continuous"`` or ``"sampled"``
        ``"auto"``: continuous-time when every state is continuous, else the
        sampled map over the base period (module docstring).
    dt : float, optional
        The major step of a sampled model (default: the largest step that
        divides every period; required when a block updates a
        floating-point discrete state at every major step).
    solver : ``"rk4"`` or ``"euler"``
        The fixed-step solver of a sampled model's continuous part.
    seed : int
        Seed of random blocks' keys (held at their operating values).

    Returns
    -------
    LinearModel
        ``A, B, C, D``, ``dt`` (0: continuous), state/input/output names,
        the operating point; ``.to_control()`` for python-control.

    Raises
    ------
    WiringError
        An unknown block or port, or an output port given as an input.
    ParameterError
        A bad operating point, parameter, ``kind`` or ``dt``.
    CompileError
        A block the compiled engine cannot trace.

    Notes
    -----
    The Jacobians are ``jax.jacfwd`` of the compiled engine's traced
    functions (exact to round-off). For many operating points or
    parameter values, keep a :class:`Linearizer` (compiled once).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> src = d.add(av.blocks.Constant([[0.0]]), name="src")
    >>> g = d.add(av.blocks.Gain(-2.0), name="g")
    >>> x = d.add(av.blocks.Integrator([[1.0]]), name="x")
    >>> s = d.add(av.blocks.Sum("++"), name="s")
    >>> _ = d.connect(x.y, g.u), d.connect(g.y, s.u0), d.connect(src.y, s.u1)
    >>> _ = d.connect(s.y, x.u)
    >>> m = av.linearize(d, inputs=["s.u1"], outputs=["x.y"])
    >>> m.A, m.B, m.C, m.D
    (array([[-2.]]), array([[1.]]), array([[1.]]), array([[0.]]))
    >>> m.states
    ['x.x[0][0]']
    """
    lin = Linearizer(diagram, inputs=inputs, outputs=outputs, kind=kind, dt=dt,
                     solver=solver, seed=seed)
    return lin(at, params=params, t=t)
