"""Built-in metrics: ``fn(results) -> scalar`` over the logged signals.

Each looks for the signals it needs by their port name and says clearly
which it needs when they were not logged.

=================  ==========================================================
name               value
=================  ==========================================================
``final_error``    RMS over agents of the last logged ``*.error`` signal
                   (formation: the leader-follower (l, alpha) errors) [m, rad]
``min_gap``        smallest distance between two agents over the whole run,
                   from the first ``*.pose`` / ``*.position`` signal [m]
``done_fraction``  fraction of agents done at the end: ``*.done``
                   (waypoints, swap) or ``*.informed`` (nest) [-]
``time_to_done``   first logged time at which every agent is done; NaN when
                   never [s]
``final_order``    last value of an ``*.order`` signal, else the order
                   parameter of the last ``*.velocity`` (flocking) [-]
``path_length``    mean distance driven per agent [m]
``collisions``     number of logged samples with any ``*.hit_*`` true [-]
=================  ==========================================================

:data:`DEFAULTS` names the metrics used when none are given, per built-in
scenario.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import AvError


class MetricError(AvError):
    """A metric could not be computed from what the run logged."""


def _find(res, suffixes, metric):
    for suf in suffixes:
        for k in res.keys():
            if k.rsplit(".", 1)[-1] == suf:
                return k
    raise MetricError(f"metric '{metric}' needs a logged signal named "
                      f"{' or '.join(repr('*.' + s) for s in suffixes)}",
                      found=sorted(res.keys()),
                      hint="log it in the scenario's simulation.log or pick another "
                           "metric")


def _positions(res, metric):
    k = _find(res, ("pose", "position"), metric)
    p = np.asarray(res[k], dtype=float)
    return p[..., :2] if k.endswith("pose") else p


def final_error(res):
    """RMS over agents of the last ``*.error`` sample."""
    e = np.asarray(res[_find(res, ("error",), "final_error")][-1], dtype=float)
    return float(np.sqrt(np.mean(np.sum(e.reshape(len(e), -1) ** 2, axis=1))))


def min_gap(res):
    """Smallest distance between any two agents over all logged samples."""
    from scipy.spatial import cKDTree
    p = _positions(res, "min_gap")
    if p.shape[1] < 2:
        return float("inf")
    best = np.inf
    for frame in p:
        d, _ = cKDTree(frame).query(frame, k=2)
        best = min(best, float(d[:, 1].min()))
    return best


def _done(res, metric):
    k = _find(res, ("done", "informed"), metric)
    return np.asarray(res[k], dtype=bool).reshape(len(res.t), -1)


def done_fraction(res):
    """Fraction of agents done (or informed) at the last sample."""
    return float(_done(res, "done_fraction")[-1].mean())


def time_to_done(res):
    """First logged time at which all agents are done; NaN when never."""
    all_done = _done(res, "time_to_done").all(axis=1)
    hit = np.flatnonzero(all_done)
    return float(res.t[hit[0]]) if len(hit) else float("nan")


def final_order(res):
    """Last value of the ``*.order`` signal; without one, the order parameter
    ``|sum_i v_i| / sum_i |v_i|`` of the last ``*.velocity`` sample."""
    if any(k.rsplit(".", 1)[-1] == "order" for k in res.keys()):
        return float(np.asarray(res[_find(res, ("order",), "final_order")])[-1])
    v = np.asarray(res[_find(res, ("order", "velocity"), "final_order")][-1], float)
    return float(np.linalg.norm(v.sum(axis=0)) / max(np.linalg.norm(v, axis=-1).sum(),
                                                      1e-300))


def path_length(res):
    """Mean over agents of the distance driven."""
    p = _positions(res, "path_length")
    return float(np.linalg.norm(np.diff(p, axis=0), axis=-1).sum(axis=0).mean())


def collisions(res):
    """Number of logged samples where any ``*.hit_*`` signal is true."""
    keys = [k for k in res.keys() if k.rsplit(".", 1)[-1].startswith("hit")]
    if not keys:
        raise MetricError("metric 'collisions' needs a logged '*.hit_*' signal",
                          found=sorted(res.keys()))
    any_hit = np.zeros(len(res.t), dtype=bool)
    for k in keys:
        any_hit |= np.asarray(res[k], dtype=bool).reshape(len(res.t), -1).any(axis=1)
    return int(any_hit.sum())


METRICS = {
    "final_error": final_error,
    "min_gap": min_gap,
    "done_fraction": done_fraction,
    "time_to_done": time_to_done,
    "final_order": final_order,
    "path_length": path_length,
    "collisions": collisions,
}

DEFAULTS = {
    "waypoints": ["done_fraction", "time_to_done", "min_gap"],
    "formation": ["final_error", "min_gap", "collisions"],
    "nest": ["done_fraction", "time_to_done"],
    "flocking": ["final_order", "min_gap"],
    "swap": ["done_fraction", "time_to_done", "min_gap"],
}
FALLBACK = ["min_gap", "path_length"]
