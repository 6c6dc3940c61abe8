"""Discrete-event supervisors: a global state machine and per-agent modes.

Semantics
---------
A machine has named states, an initial state and an ordered list of
transitions ``(source, target, guard)``. The state is an integer discrete
state; at every major step the block evaluates every guard as a function of
its inputs, ``guard(u, xp) -> bool`` (``u`` the input dict, plus ``u["t"]``
the time), and takes the *first listed* transition out of the current state
whose guard is true; if none is, the state is kept. One transition per
step (no chaining). Outputs depend only on the state (a table of values per
state, plus ``mode``), so the inputs are not direct feedthrough and a
supervisor never closes an algebraic loop. The update is pure: guards are
evaluated for all transitions and combined with ``where``.

:class:`Supervisor` has one scalar state (switch formations, phases of a
mission: the role Stateflow plays in the AVLib case study IV.D);
:class:`AgentModes` has one state per agent with vectorised guards returning
``(N,)`` booleans (e.g. searching / informed / returning).

Definitions are checked when the block is built: unique state names, known
initial state and transition ends, callable guards, an output value for
every state (same shape), and every state reachable from the initial one.
``Supervisor.from_statemachine`` reads a python-statemachine class (the
optional extra ``avblocks[supervisor]``): its own definition checks apply
too, and its transitions' ``cond`` names select the guard functions.

Reference: AVLib paper, Section IV.D; D. Harel, "Statecharts", Sci. Comput.
Program. 8(3), 1987.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError


def _always(u, xp):
    return True


def _is_name(s):
    return isinstance(s, str) and bool(s)


def _validate(block, states, transitions, initial, outputs):
    if isinstance(states, (str, bytes, dict)) or not isinstance(states, (list, tuple)):
        raise ParameterError("states must be a list of unique non-empty names",
                             block=block, param="states", expected="list of str",
                             found=repr(states)[:60])
    states = list(states)
    if not states or not all(_is_name(s) for s in states) or len(set(states)) != len(states):
        raise ParameterError("states must be unique non-empty names", block=block,
                             param="states", found=states)
    index = {s: i for i, s in enumerate(states)}
    if not isinstance(transitions, (list, tuple)):
        raise ParameterError("transitions must be a list of (source, target[, guard])",
                             block=block, param="transitions",
                             expected="list of tuples", found=repr(transitions)[:60])
    if outputs is not None and not isinstance(outputs, dict):
        raise ParameterError("outputs must map output names to {state: value}",
                             block=block, param="outputs", expected="dict",
                             found=repr(outputs)[:60])
    src, dst, guards = [], [], []
    for k, tr in enumerate(transitions):
        if not isinstance(tr, (list, tuple)):
            raise ParameterError(f"transition {k} is not (source, target[, guard])",
                                 block=block, param="transitions", found=repr(tr)[:60])
        if len(tr) == 2:
            tr = (*tr, _always)
        if len(tr) != 3:
            raise ParameterError("a transition is (source, target[, guard])", block=block,
                                 param="transitions", found=tr)
        s, d, g = tr
        for end in (s, d):
            if not _is_name(end) or end not in index:
                raise ParameterError(f"transition {k} names an unknown state", block=block,
                                     param="transitions", expected=states, found=end)
        if not callable(g):
            raise ParameterError(f"guard of transition {k} is not callable", block=block,
                                 param="transitions", found=repr(g)[:60])
        src.append(index[s])
        dst.append(index[d])
        guards.append(g)
    try:
        init = np.atleast_1d(np.asarray(initial, dtype=object))
    except (TypeError, ValueError):
        raise ParameterError("initial must be a state name or one per agent", block=block,
                             param="initial", expected=states,
                             found=repr(initial)[:60]) from None
    if init.ndim != 1:
        raise ParameterError("initial must be a state name or a list of them",
                             block=block, param="initial", expected=states,
                             found=repr(initial)[:60])
    for s in init:
        if not _is_name(s) or s not in index:
            raise ParameterError("unknown initial state", block=block, param="initial",
                                 expected=states, found=s)
    init_idx = np.array([index[s] for s in init], dtype=np.int64)
    # reachability from the initial state(s)
    seen, todo = set(init_idx.tolist()), deque(init_idx.tolist())
    while todo:
        i = todo.popleft()
        for s, d in zip(src, dst):
            if s == i and d not in seen:
                seen.add(d)
                todo.append(d)
    unreachable = [states[i] for i in range(len(states)) if i not in seen]
    if unreachable:
        raise ParameterError("states unreachable from the initial state", block=block,
                             param="transitions", found=unreachable)
    tables = {}
    for name, per_state in (outputs or {}).items():
        if not isinstance(per_state, dict) or set(per_state) != set(states):
            raise ParameterError(f"output {name!r} needs a value for every state",
                                 block=block, param="outputs", expected=states,
                                 found=sorted(per_state) if isinstance(per_state, dict)
                                 else per_state)
        if not _is_name(name):
            raise ParameterError("output names must be non-empty strings", block=block,
                                 param="outputs", found=repr(name)[:60])
        try:
            vals = [np.asarray(per_state[s]) for s in states]
        except (TypeError, ValueError):
            raise ParameterError(f"output {name!r} needs one array value per state",
                                 block=block, param="outputs") from None
        if any(v.dtype.kind not in "biuf" for v in vals):
            raise ParameterError(f"output {name!r} values must be numbers or bools",
                                 block=block, param="outputs",
                                 found=sorted({v.dtype.name for v in vals}))
        if len({v.shape for v in vals}) != 1:
            raise ParameterError(f"output {name!r} has different shapes per state",
                                 block=block, param="outputs",
                                 found={s: v.shape for s, v in zip(states, vals)})
        tables[name] = np.stack(vals)
    return states, np.array(src, np.int64), np.array(dst, np.int64), guards, init_idx, tables


def _input_shape(block, name, shape):
    """An input's declared shape as a tuple of whole numbers >= 0."""
    if not _is_name(name):
        raise ParameterError("input names must be non-empty strings", block=block,
                             param="inputs", found=repr(name)[:60])
    if isinstance(shape, np.ndarray) and shape.ndim <= 1:
        shape = shape.tolist()
    if shape is None:
        return ()
    dims = tuple(shape) if isinstance(shape, (tuple, list)) else (shape,)
    if not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) and k >= 0
               for k in dims):
        raise ParameterError(f"input {name!r} needs a shape of whole numbers",
                             block=block, param="inputs", expected="int or tuple of int",
                             found=repr(shape)[:60])
    return tuple(int(k) for k in dims)


def fire(mode, fired, src, dst, xp=np):
    """Next mode: the first transition (in list order) out of ``mode`` whose
    guard ``fired[k]`` holds; else ``mode``. ``fired`` a list of bool arrays."""
    new = mode
    for k in range(len(fired) - 1, -1, -1):
        new = xp.where((mode == int(src[k])) & fired[k], int(dst[k]), new)
    return new


class _Machine(Block):
    _per_agent = False

    def __init__(self, states, transitions, *, initial, outputs=None, inputs=None, n=None):
        super().__init__()
        name = type(self).__name__
        (self.states, self.src, self.dst, self.guards, init,
         self.tables) = _validate(name, states, transitions, initial, outputs)
        if inputs is not None and not isinstance(inputs, dict):
            raise ParameterError("inputs must map input names to shapes", block=name,
                                 param="inputs", expected="dict", found=repr(inputs)[:60])
        if self._per_agent:
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
                raise ParameterError("n must be a positive whole number of agents",
                                     block=name, param="n", expected="int >= 1",
                                     found=repr(n)[:60])
            self.n = n = int(n)
            init = np.broadcast_to(init, (n,)).copy() if init.size in (1, n) else None
            if init is None:
                raise ParameterError("initial must be one state or one per agent",
                                     block=name, param="initial")
            self._shape = (n,)
        else:
            if init.size != 1:
                raise ParameterError("a Supervisor has one initial state", block=name,
                                     param="initial")
            init = init.reshape(())
            self._shape = ()
        self.declare_discrete_state("mode", init, dtype=np.int64,
                                    agents=self._per_agent)
        for nm, spec in (inputs or {}).items():
            shape, dtype = (spec if isinstance(spec, tuple) and len(spec) == 2
                            and isinstance(spec[1], str) else (spec, "float64"))
            self.declare_input(nm, _input_shape(name, nm, shape), dtype,
                               feedthrough=False, agents=self._per_agent)
        self.declare_output("mode", self._shape, "int64", agents=self._per_agent)
        for nm, tab in self.tables.items():
            shp = (*self._shape, *tab.shape[1:]) if self._per_agent else tab.shape[1:]
            self.declare_output(nm, shp, tab.dtype.name, agents=self._per_agent)

    def state_index(self, name):
        return self.states.index(name)

    def output(self, t, x, u, xp):
        m = x["mode"]
        y = {"mode": m}
        for nm, tab in self.tables.items():
            y[nm] = xp.asarray(tab)[m]
        return y

    def update(self, t, x, u, xp):
        uu = {**u, "t": t}
        fired = [xp.broadcast_to(xp.asarray(g(uu, xp), dtype=bool), self._shape)
                 for g in self.guards]
        return {"mode": fire(x["mode"], fired, self.src, self.dst, xp)}


class Supervisor(_Machine):
    """A discrete-event state machine block (global state), e.g. formation switching.

    Ports
    -----
    inputs : declared by ``inputs={name: shape or (shape, dtype)}`` (not
        feedthrough); guards read them.
    mode : out, () int64 — index of the current state in ``states``.
    <output> : out — ``outputs[name][state]`` for the current state.

    Parameters
    ----------
    states : list of str;  initial : str.
    transitions : list of ``(source, target, guard)``, ``guard(u, xp) -> bool``
        (``(source, target)``: always); the first true one out of the
        current state fires at a major step.
    outputs : ``{name: {state: value}}``.

    No numeric parameters: states, transitions (guards are Python callables)
    and the output tables are structural (a mode machine, not a gain).

    Examples
    --------
    >>> import numpy as np
    >>> s = Supervisor(["line", "column"], [("line", "column", lambda u, xp: u["gap"][0] < 2),
    ...                ("column", "line", lambda u, xp: u["gap"][0] > 3)],
    ...                initial="line", inputs={"gap": (1,)}, outputs={"spacing": {
    ...                "line": 1.0, "column": 0.5}})
    >>> x = s.initial_state()
    >>> x = s.update(0.0, x, {"gap": np.array([1.0])}, np)
    >>> s.states[int(x["mode"])], float(s.output(0.0, x, {}, np)["spacing"])
    ('column', 0.5)
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {'states': ['off', 'on'],
               'transitions': [['off',
                                'on',
                                {'guard': {'input': 'u',
                                           'index': [0],
                                           'op': '>=',
                                           'value': 1.0}}],
                               ['on',
                                'off',
                                {'guard': {'input': 'u',
                                           'index': [0],
                                           'op': '<',
                                           'value': 0.0}}]],
               'initial': 'off',
               'inputs': {'u': [1]}}

    @classmethod
    def from_statemachine(cls, machine, *, guards=None, outputs=None, inputs=None):
        """Build from a python-statemachine ``StateMachine`` class.

        Its states (and initial state) and transitions are read; each
        transition's ``cond`` names guard functions in ``guards`` (all must
        hold); a transition without ``cond`` always fires. Requires the
        optional extra ``python-statemachine``.
        """
        try:
            import statemachine  # noqa: F401
        except ImportError:  # pragma: no cover - optional extra
            raise ParameterError("from_statemachine needs python-statemachine",
                                 block="Supervisor",
                                 hint="pip install 'avblocks[supervisor]'") from None
        guards = dict(guards or {})
        sts = list(machine.states)
        states = [s.id for s in sts]
        initial = [s.id for s in sts if s.initial]
        trans = []
        for s in sts:
            for tr in s.transitions:
                names = [str(c) for c in tr.cond]
                missing = [c for c in names if c not in guards]
                if missing:
                    raise ParameterError("cond names without a guard function",
                                         block="Supervisor", param="guards",
                                         expected=sorted(guards), found=missing)
                fns = [guards[c] for c in names]

                def g(u, xp, fns=fns):
                    ok = True
                    for f in fns:
                        ok = ok & xp.asarray(f(u, xp), dtype=bool)
                    return ok
                trans.append((tr.source.id, tr.target.id, g))
        return cls(states, trans, initial=initial[0] if initial else None,
                   outputs=outputs, inputs=inputs)


class AgentModes(_Machine):
    """Per-agent discrete modes (N independent copies of one state machine).

    Ports
    -----
    inputs : declared by ``inputs={name: shape}``, full shapes with the agent
        axis first (not feedthrough).
    mode : out, (N,) int64;  <output> : out, (N, ...) per-agent table lookup.

    Parameters
    ----------
    n : int;  states, transitions, outputs: as :class:`Supervisor`, but each
    guard returns an (N,) bool array (vectorised over agents; a scalar is
    broadcast);  initial : one state name or (N,) names.
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {'n': '$agents',
               'states': ['off', 'on'],
               'transitions': [['off',
                                'on',
                                {'guard': {'input': 'u', 'op': '>=', 'value': 1.0}}]],
               'initial': 'off',
               'inputs': {'u': ['$agents']}}

    _per_agent = True

    def __init__(self, n, states, transitions, *, initial, outputs=None, inputs=None):
        super().__init__(states, transitions, initial=initial, outputs=outputs,
                         inputs=inputs, n=n)
