"""The compiled engine's side of the engine contract (:mod:`avblocks.core.frontend`).

``simulate(..., backend="jax")`` lands here: the whole run is traced and
compiled once per diagram structure (:func:`~avblocks.core.compiled.compile`)
and a second run with other numbers reuses the executable. ``compile`` is
the engine's ahead-of-time entry (:func:`avblocks.compile` lands there).
"""

from __future__ import annotations

from .build import compile, simulate_compiled  # noqa: F401  (compile: the contract's)


def run(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=None, seed=0,
        t0=0.0, realtime=None, progress=None, check_finite=True,
        max_log_bytes=2 * 1024**3, params=None, x0=None, **options):
    """Run ``diagram`` compiled (arguments and result as :func:`avblocks.simulate`;
    options ``dtype`` and ``cache``). ``log_every=None`` logs every step."""
    return simulate_compiled(diagram, t_final, dt, solver, log=log,
                             log_every=1 if log_every is None else log_every,
                             seed=seed, t0=t0, realtime=realtime, progress=progress,
                             check_finite=check_finite, max_log_bytes=max_log_bytes,
                             params=params, x0=x0, backend="jax", **options)
