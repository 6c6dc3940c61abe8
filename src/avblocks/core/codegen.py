"""A NumPy major step written out once per compiled diagram.

:class:`~avblocks.core.engine.Engine` evaluates a diagram generically: it
loops over blocks, gathers inputs from lists of dicts, copies lists and
merges dicts at every stage. That generality costs tens of microseconds per
step, which dominates small fleets. :func:`make_step` instead writes the
major step of one diagram and one fixed-step solver (Euler or RK4) as
straight-line Python source: every block method bound to a local, every
input resolved to the producing block's output dict, periodic hits tested
with integer arithmetic on the step index, only the outputs that feed
continuous states recomputed inside solver stages. It is compiled once with
:func:`exec` and called at every step.

Semantics are those of the engine, operation for operation, so results are
bit for bit the same (``tests/core/test_codegen.py`` checks it on every
kind of diagram); the block contract is unchanged (blocks receive and
return dicts). Anything else (variable-step solvers, custom Solver objects,
JAX) keeps using the engine.

The generated function is ``step(X, Y, t, t1, k) -> (X, Y)`` with ``X``,
``Y`` lists (one dict per block, evaluation order) of states and outputs at
``t = t_k``; it returns new lists at ``t1 = t_{k+1}``. Print
``make_step(...).source`` to read it.
"""

from __future__ import annotations

import functools

import numpy as np

from .errors import SimulationError
from .solvers import RK4, Euler


def supported(solver) -> bool:
    """True when :func:`make_step` can write the step for ``solver``."""
    return type(solver) in (Euler, RK4)


class _Writer:
    def __init__(self):
        self.lines = []
        self.ind = 1

    def __call__(self, line):
        self.lines.append("    " * self.ind + line)


def make_step(eng, solver):
    """The generated major step for engine ``eng`` (NumPy) and ``solver``."""
    blocks, nb = eng.blocks, len(eng.blocks)
    env = {"np": np, "_SimulationError": SimulationError, "_dict": dict}
    w = _Writer()
    cont, disc = eng.cont, eng.disc
    periodic = eng.periodic

    for i, b in enumerate(blocks):
        env[f"out{i}"] = b.output
        if b._cstates:
            env[f"der{i}"] = b.derivative
        if b._dstates:
            env[f"upd{i}"] = b.update

    def hit(i, kvar):
        off, per = eng.off_k[i], eng.per_k[i]
        if per == 1:
            return f"{kvar} >= {off}"
        if off == 0:
            return f"{kvar} % {per} == 0"
        return f"{kvar} >= {off} and ({kvar} - {off}) % {per} == 0"

    def u_all(i, ymap):
        items = ", ".join(f"{inp!r}: {ymap(s)}[{o!r}]" for inp, s, o in eng.src[i])
        return "{" + items + "}"

    def u_ft(i, ymap):
        items = ", ".join(f"{inp!r}: {ymap(s)}[{o!r}]" for inp, s, o in eng.src_ft[i])
        return "{" + items + "}"

    def call_out(i, tvar, xvar, ymap, target):
        w(f"{target} = out{i}({tvar}, {xvar}, {u_ft(i, ymap)}, np)")
        w(f"if {target}.__class__ is not _dict:")
        w(f"    {target} = _wrap{i}({target}, {tvar})")
        env[f"_wrap{i}"] = _wrapper(eng, i)

    # ---- load
    for i in range(nb):
        w(f"x{i} = X[{i}]")
        w(f"y{i} = Y[{i}]")
    # ---- 1. discrete updates at t_k
    for i in disc:
        b = blocks[i]
        body = []
        extra = f", y=y{i}" if b.update_uses_outputs else ""
        body.append(f"n_ = upd{i}(t, x{i}, {u_all(i, lambda s: f'y{s}')}, np{extra})")
        body.append(f"x{i} = {{**x{i}, **n_}}")
        if periodic[i]:
            w(f"if {hit(i, 'k')}:")
            for line in body:
                w("    " + line)
        else:
            for line in body:
                w(line)

    # ---- 2. continuous states from t_k to t_k+1
    def derivs(tvar, xname, ymap, kname):
        for i in cont:
            w(f"{kname}{i} = der{i}({tvar}, {xname(i)}, {u_all(i, ymap)}, np)")

    def new_state(i, expr_of):
        names = eng.cont_names[i]
        pairs = ", ".join(f"{nm!r}: {expr_of(nm)}" for nm in names)
        if set(blocks[i]._dstates) or set(names) != set(blocks[i]._cstates):
            return f"{{**x{i}, {pairs}}}"
        return "{" + pairs + "}"

    if cont:
        if type(solver) is Euler:
            derivs("t", lambda i: f"x{i}", lambda s: f"y{s}", "k1_")
            for i in cont:
                w(f"x{i} = " + new_state(i, lambda nm, i=i:
                                         f"x{i}[{nm!r}] + h * k1_{i}[{nm!r}]"))
        else:                                   # RK4, as RK4.step writes it
            w("hh = 0.5 * h")
            w("tm = t + 0.5 * h")
            w("te = t + h")
            derivs("t", lambda i: f"x{i}", lambda s: f"y{s}", "k1_")
            minor_list = _stage_blocks(eng)
            minor = set(minor_list)

            def stage(prev_k, coef, tvar, kname):
                for i in cont:
                    w(f"s{i} = " + new_state(i, lambda nm, i=i:
                                             f"x{i}[{nm!r}] + {coef} * {prev_k}{i}[{nm!r}]"))

                def xname(i):
                    return f"s{i}" if i in cont else f"x{i}"

                def ymap(s):
                    return f"z{s}" if s in minor else f"y{s}"

                for i in minor_list:
                    call_out(i, tvar, xname(i), ymap, f"z{i}")
                derivs(tvar, xname, ymap, kname)

            stage("k1_", "hh", "tm", "k2_")
            stage("k2_", "hh", "tm", "k3_")
            stage("k3_", "h", "te", "k4_")
            w("c6 = h / 6")
            w("c3 = h / 3")
            for i in cont:
                w(f"x{i} = " + new_state(i, lambda nm, i=i: (
                    f"x{i}[{nm!r}] + c6 * k1_{i}[{nm!r}] + c3 * k2_{i}[{nm!r}] "
                    f"+ c3 * k3_{i}[{nm!r}] + c6 * k4_{i}[{nm!r}]")))

    # ---- 3. outputs at t_k+1 (periodic blocks only at their hits)
    for i in eng.with_outputs:
        if periodic[i]:
            w(f"if {hit(i, 'k1')}:")
            w.ind += 1
            call_out(i, "t1", f"x{i}", lambda s: f"y{s}", f"y{i}")
            w.ind -= 1
        else:
            call_out(i, "t1", f"x{i}", lambda s: f"y{s}", f"y{i}")
    xs = ", ".join(f"x{i}" for i in range(nb))
    ys = ", ".join(f"y{i}" for i in range(nb))
    w(f"return [{xs}], [{ys}]")
    head = ["def step(X, Y, t, t1, k, h):", "    k1 = k + 1"]
    src = "\n".join(head + w.lines) + "\n"
    code = _compiled(src)
    exec(code, env)  # noqa: S102 - our own generated source, no user text in it
    fn = env["step"]
    fn.source = src
    return fn


@functools.lru_cache(maxsize=64)
def _compiled(src):
    """The code object of a generated step's source, kept for the 64 most
    recent: a sweep or a benchmark that simulates the same structure again
    and again skips Python's compiler (0.3-0.4 ms a call, a third of a short
    run's set-up). The source holds no values, only block indices and port
    names, so equal source means equal code; each call of :func:`make_step`
    still binds its own blocks' methods."""
    return compile(src, "<avblocks generated step>", "exec")


def _stage_blocks(eng):
    """Blocks whose outputs a solver stage must recompute, in evaluation
    order: the non-periodic ancestors, through feedthrough wires, of the
    inputs of continuous blocks, stopping at periodic blocks (they hold
    their outputs during stages, so what feeds them is not needed there).
    A subset of ``eng.minor``; the values derivatives see are the same."""
    need = set()
    stack = [s for i in eng.cont for (_inp, s, _o) in eng.src[i]]
    while stack:
        j = stack.pop()
        if j in need or eng.periodic[j]:
            continue
        need.add(j)
        ft = eng.blocks[j].feedthrough
        stack += [s for (inp, s, _o) in eng.src[j] if inp in ft]
    return [i for i in eng.minor if i in need]


def _wrapper(eng, i):
    """Wrap a bare array returned by a one-output block into its dict (the
    engine's rule), or raise as the engine does."""
    name = eng.single_out[i]
    block = eng.names[i]

    def wrap(y, t):
        if isinstance(y, dict):          # a dict subclass
            return y
        if name is None:
            raise SimulationError(
                "output() must return a dict {port: array} for a block with "
                "several outputs", block=block, time=t, found=type(y).__name__)
        return {name: y}
    return wrap
