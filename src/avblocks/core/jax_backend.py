"""Compatibility entry point: :func:`simulate_jax` is
``simulate(..., backend="jax")``. The compiled backend lives in
:mod:`avblocks.core.compiled`."""

from __future__ import annotations


def simulate_jax(diagram, t_final, dt=0.01, solver="rk4", *, log=None, seed=0,
                 t0=0.0, x64=True, **kw):
    """Simulate with JAX; same as ``simulate(..., backend="jax")`` (``x64=False``
    is ``dtype="float32"``)."""
    from .compiled import simulate_compiled
    return simulate_compiled(diagram, t_final, dt, solver, log=log, seed=seed, t0=t0,
                             dtype="float64" if x64 else "float32", **kw)
