"""Trace a whole diagram under JAX: ``jit`` of one ``lax.scan`` over steps.

This runs the same :class:`~avblocks.core.engine.Engine` the NumPy loop uses,
with ``xp = jax.numpy``: that only works because blocks are pure functions
of the values they are handed. Fixed-step solvers only; no side effects.

    res = simulate_jax(diagram, 30.0, dt=0.01, log=[fleet.pose])
"""

from __future__ import annotations

import numpy as np

from .diagram import Diagram
from .engine import Engine
from .errors import AvError, ParameterError
from .results import Results
from .simulator import Simulator, default_log
from .solvers import make_solver


def simulate_jax(diagram, t_final, dt=0.01, solver="rk4", *, log=None, seed=0,
                 t0=0.0, x64=True):
    """Simulate with JAX (``jit`` + ``lax.scan``); returns :class:`Results`.

    Requires the ``jax`` extra. Side-effect blocks are rejected. With
    ``x64`` (default) JAX computes in float64 and matches the NumPy run to
    round-off.
    """
    try:
        import jax
        import jax.numpy as jnp
    except ImportError as e:  # pragma: no cover - depends on the extra
        raise AvError("simulate_jax needs JAX: pip install 'avblocks[jax]'") from e
    if x64:
        jax.config.update("jax_enable_x64", True)
    compiled = diagram.build() if isinstance(diagram, Diagram) else diagram
    for n, b in zip(compiled.names, compiled.blocks, strict=True):
        if b.side_effects:
            raise ParameterError("side-effect blocks cannot be traced", block=n)
    solv = make_solver(solver)
    if not solv.fixed_step:
        raise ParameterError("simulate_jax supports fixed-step solvers only",
                             param="solver", expected="'rk4' or 'euler'", found=solver)
    sim = Simulator(compiled, dt, solv, seed=seed, t0=t0)   # for seeding/checks
    eng = Engine(compiled, dt, xp=jnp)
    refs = default_log(compiled) if log is None else list(log)
    idx = [compiled.resolve(r) for r in refs]
    names = [f"{compiled.names[i]}.{o}" for i, o in idx]
    nsteps = int(round((float(t_final) - t0) / dt))
    X0 = jax.tree_util.tree_map(jnp.asarray, sim.initial_states())
    Y0 = eng.all_outputs(t0, X0, [dict() for _ in compiled.blocks])

    def body(carry, k):
        X, Y = carry
        t = t0 + k * dt
        X = eng.update(t, X, Y, eng.hits(k))
        X = solv.step(eng, t, X, Y, dt)
        Y = eng.major_outputs(t0 + (k + 1) * dt, X, Y, eng.hits(k + 1))
        return (X, Y), [Y[i][o] for i, o in idx]

    @jax.jit
    def run(X0, Y0):
        _, logs = jax.lax.scan(body, (X0, Y0), jnp.arange(nsteps))
        return logs

    logs = run(X0, Y0)
    data = {n: np.concatenate([np.asarray(Y0[i][o])[None], np.asarray(l)])
            for n, (i, o), l in zip(names, idx, logs, strict=True)}
    t = t0 + dt * np.arange(nsteps + 1)
    ports = {n: compiled.blocks[i]._outputs[o] for n, (i, o) in zip(names, idx, strict=True)}
    return Results(t, data, ports, {"solver": solv.name, "dt": dt, "backend": "jax",
                                    "steps": nsteps, "seed": seed})
