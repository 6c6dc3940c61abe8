"""The live engine's side of the engine contract (:mod:`avblocks.core.frontend`).

``simulate(..., live=True)`` lands here: a :class:`~avblocks.viz.live.LiveView`
steps the NumPy engine's :class:`~avblocks.core.simulator.Simulator` paced to
the wall clock and draws it in the browser.
"""

from __future__ import annotations


def run(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=None, seed=0,
        t0=0.0, realtime=None, progress=None, check_finite=True,
        max_log_bytes=2 * 1024**3, params=None, x0=None, live=True):
    """Run ``diagram`` in the browser (arguments and result as
    :func:`avblocks.simulate`; option ``live``: True or LiveView options).
    ``progress`` is ignored: the page shows the run."""
    from .view import simulate_live
    return simulate_live(diagram, t_final, dt, solver, live=live, log=log,
                         log_every=log_every, seed=seed, t0=t0, realtime=realtime,
                         check_finite=check_finite, max_log_bytes=max_log_bytes,
                         params=params, x0=x0)
