"""What a compiled run hands back, checked: :func:`check_finite` (NaN/inf in
the logged signals or the final state raise :class:`SimulationError` with
the results attached)."""

from __future__ import annotations

import numpy as np

from ..errors import SimulationError


def check_finite(res):
    """Raise SimulationError (results attached) if a logged float signal or
    the final state is NaN/inf: the first sample and signal that is."""
    axis0 = 1 if res.runs is not None else 0
    first, where = None, None
    for k, v in res.data.items():
        if v.dtype.kind != "f" or np.isfinite(v).all():
            continue
        bad = ~np.isfinite(v)
        per_t = bad.reshape(*v.shape[:axis0 + 1], -1).any(-1)
        if axis0:
            per_t = per_t.any(0)
        j = int(np.argmax(per_t))
        if first is None or j < first:
            first, where = j, k
    if where is None:
        for k, v in res.final_state.items():
            if np.asarray(v).dtype.kind == "f" and not np.isfinite(v).all():
                b, _, nm = k.rpartition(".")
                raise SimulationError(
                    f"state '{nm}' is NaN or infinite at the end of the run",
                    block=b, results=res,
                    hint="log more signals (or check_finite=False) to find where; the "
                         "NumPy backend stops at the first step and names the block")
        return
    b, _, port = where.rpartition(".")
    runs = ""
    if res.runs is not None:
        v = res.data[where]
        bad = ~np.isfinite(v.reshape(v.shape[0], -1)).all(-1)
        runs = f" in run(s) {np.flatnonzero(bad)[:10].tolist()}"
    raise SimulationError(f"logged output is NaN or infinite{runs}", block=b, port=port,
                          time=float(res.t[first]), results=res,
                          hint="the NumPy backend stops at the first bad step and "
                               "names the block that produced it")
