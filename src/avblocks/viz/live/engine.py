"""The live engine's side of the engine contract (:mod:`avblocks.core.frontend`).

``simulate(..., live=True)`` lands here: a :class:`~avblocks.viz.live.LiveView`
steps the NumPy engine's :class:`~avblocks.core.simulator.Simulator` paced to
the wall clock and draws it in the browser.
"""

from __future__ import annotations

import sys

from .view import LiveView


def _in_notebook():
    ip = sys.modules.get("IPython")
    if ip is None:
        return False
    try:
        shell = ip.get_ipython()
    except Exception:  # noqa: BLE001 - not in IPython
        return False
    return shell is not None and hasattr(shell, "kernel")



def run(diagram, t_final, dt=0.01, solver="rk4", *, log=None, log_every=None, seed=0,
        t0=0.0, realtime=None, progress=None, check_finite=True,
        max_log_bytes=2 * 1024**3, params=None, x0=None, live=True):
    """Run ``diagram`` in the browser (arguments and result as
    :func:`avblocks.simulate`; option ``live``: True or LiveView options).
    ``progress`` is ignored: the page shows the run."""
    return simulate_live(diagram, t_final, dt, solver, live=live, log=log,
                         log_every=log_every, seed=seed, t0=t0, realtime=realtime,
                         check_finite=check_finite, max_log_bytes=max_log_bytes,
                         params=params, x0=x0)


def simulate_live(diagram, t_final, dt=0.01, solver="rk4", *, live=True, progress=None,
                  **kw):
    """:func:`avblocks.simulate` with ``live=True`` (or a dict of
    :class:`LiveView` options): serve the page, run, return the results.
    In a notebook the page is shown in the cell's output."""
    options = dict(live) if isinstance(live, dict) else {}
    if kw.get("realtime", "unset") is None and "realtime" not in options:
        kw["realtime"] = 1.0
    kw.update(options)
    view = LiveView(diagram, t_final, dt, solver, **kw)
    if _in_notebook():
        view._start_server()
        from IPython.display import display
        display(view.iframe())
    return view.run()
