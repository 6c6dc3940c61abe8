"""The few engine internals the environments step with, imported in one place.

The environments advance a diagram one control step at a time, which the
public run API (``simulate``, ``compile``) does not offer: they use the
engines' pure pieces (outputs, updates, a solver step) directly. Should the
engines move, only this module changes.
"""

from __future__ import annotations

import numpy as np

from ..core import rng
from ..core.engine import Engine
from ..core.params import bound_parameters
from ..core.solvers import make_solver


def traced_engine(compiled, dt, jnp, canon):
    """The compiled backend's engine (errors name the block, fixed dtypes).

    Like a compiled run, an environment keeps a tally of what its neighbour
    searches needed (:mod:`avblocks.core.diagnostics`; :func:`need_rows`,
    :func:`tally`), carried in its state, and checks it on the host
    (:func:`overflows`), never by a callback per step."""
    from ..core.compiled.engine import TracedEngine
    return TracedEngine(compiled, dt, jnp, canon)


def plan_searches(compiled, dt):
    """Plan the neighbour searches of ``compiled`` as the compiled engine
    does (from the plan book, or the block inputs at ``t0``)."""
    from ..core.compiled.plans import plan_searches as plan
    return plan(compiled, dt=dt)


def need_rows(compiled):
    """``{(block name, search number): row}`` of the needs tally."""
    from ..core import diagnostics
    return diagnostics.rows_of(compiled.blocks, compiled.names)


def tally(rows, value):
    """Reports of the searches traced inside go to a tally starting from
    ``value`` (see :func:`avblocks.core.diagnostics.tally`)."""
    from ..core import diagnostics
    return diagnostics.tally(rows, value)


def overflows(compiled, rows, value):
    """``[(block name, search, need, message)]`` of the searches whose need
    in ``value`` (a tally, or tallies stacked on leading axes: the largest
    counts) exceeds their plan."""
    from ..core.compiled.plans import overflows as over
    v = np.asarray(value)
    v = v.reshape((-1,) + v.shape[-2:]).max(axis=0)
    return over(compiled, {k: v[r] for k, r in rows.items()})


def jax():
    """The ``jax`` module (deferred import with avblocks' install hint)."""
    from ..core.compiled import require_jax
    return require_jax()


def float32_on_device(x):
    """``x`` as a float32 device array: cast by NumPy, then only transferred.
    (In JAX 0.10, ``jnp.asarray`` of a NumPy array and ``jnp.full`` compile
    a one-op program for each new shape; ``device_put`` compiles nothing.)"""
    return jax().device_put(np.array(x, np.float32))


def outputs_of(eng, which, t, X, Y, hits):
    """``eng.major_outputs`` restricted to the blocks ``which`` (a set of
    indices closed under feedthrough descendants); the others keep ``Y``."""
    from ..core.engine import select
    Y = list(Y)
    for i in eng.with_outputs:
        if i not in which:
            continue
        if eng.periodic[i]:
            h = hits[i]
            if h is False:
                continue
            Y[i] = select(h, eng._out(i, t, X, Y), Y[i], eng.xp)
        else:
            Y[i] = eng._out(i, t, X, Y)
    return Y


def advance(eng, solver, after_action, X, Y, k, dt, substeps):
    """One control step of ``substeps`` major steps from step ``k`` after a
    new action was written into ``X``: ``(X, Y, k)`` with ``Y`` the major
    outputs at the new step. ``Y`` on entry holds the outputs at ``k`` for
    the old action, so only the action's feedthrough descendants
    (``after_action``) are recomputed first (the same values as a full
    sweep, half the work: sensors are not evaluated twice per step)."""
    for sub in range(substeps):
        t = k * dt
        hit = eng.hits(k)
        if sub == 0:
            Y = outputs_of(eng, after_action, t, X, Y, hit)
        else:
            Y = eng.major_outputs(t, X, Y, hit)
        X = eng.update(t, X, Y, hit)
        X = solver.step(eng, t, X, Y, dt)
        k = k + 1
    return X, eng.major_outputs(k * dt, X, Y, eng.hits(k)), k


__all__ = ["advance", "outputs_of", "Engine", "bound_parameters", "make_solver", "rng",
           "traced_engine", "jax", "plan_searches", "need_rows", "tally", "overflows"]
