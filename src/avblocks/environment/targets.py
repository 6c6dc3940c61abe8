"""Target detection for search and pickup: agents find point targets.

Agent ``i`` detects target ``j`` when ``|p_i - q_j| <= R_i + r_j`` (sensing
radius ``R_i`` of the agent, radius ``r_j`` of the target). Candidate pairs
come from one cell-list search of the targets around every agent
(:class:`avblocks.utility.spatial.NeighborSearch` with ``queries=``, cells of
edge ``max R + max r``), so the cost is ~ N (targets per cell) and no (N, M)
array is formed. Traceable: the NumPy and compiled engines give the same
detections (exact: comparisons of the same distances).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..utility.spatial import NeighborSearch
from ._common import agent_count, declare_agents_input, maybe_periodic

_TINY_REACH = 1e-6      # cell edge when every radius is 0 (coincidence only)


def _reach(sensing_radius, target_radius):
    return max(float(np.max(sensing_radius, initial=0.0)) +
               float(np.max(target_radius, initial=0.0)), _TINY_REACH)


def detect_targets(pos, targets, sensing_radius, target_radius, active=None, xp=np,
                   search=None):
    """Nearest detected target per agent.

    Returns ``target`` (N,) int64 (index of the nearest detected target,
    -1 if none; ties in distance go to the smaller index) and ``hits`` (M,)
    bool (targets seen by at least one agent). Targets with ``active[j]``
    false are ignored. ``search`` is the :class:`NeighborSearch` over the
    targets (a fresh one if None; a compiled caller passes a planned one).
    """
    pos = xp.asarray(pos)[:, :2]
    targets = xp.asarray(targets)
    n, m = pos.shape[0], targets.shape[0]
    ity = np.int64 if xp is np else xp.asarray(0).dtype
    if n == 0 or m == 0:
        return xp.full((n,), -1, dtype=ity), xp.zeros((m,), dtype=bool)
    R = xp.broadcast_to(xp.asarray(sensing_radius), (n,))
    r = xp.broadcast_to(xp.asarray(target_radius), (m,))
    if search is None:
        search = NeighborSearch(_reach(sensing_radius, target_radius), points="targets")
    idx, dist = search.within(targets, xp.max(R) + xp.max(r), queries=pos, xp=xp)
    j = xp.maximum(idx, 0)
    ok = (idx >= 0) & (dist <= R[:, None] + r[j])
    if active is not None:
        ok = ok & xp.asarray(active)[j]
    dd = xp.where(ok, dist, xp.inf)
    dmin = xp.min(dd, axis=1, keepdims=True)
    big = np.iinfo(np.int32).max
    best = xp.min(xp.where(ok & (dd == dmin), idx, big), axis=1)
    best = xp.where(best == big, -1, best).astype(ity)
    flat, w = xp.where(ok, idx, 0).reshape(-1), ok.reshape(-1).astype(float)
    if xp is np:
        hits = np.bincount(flat, weights=w, minlength=m)
    else:
        hits = xp.bincount(flat, weights=w, length=m)
    return best, hits > 0


class TargetDetection(Block):
    """Agents detecting point targets (with radii) within a sensing radius.

    Ports
    -----
    pose : in, (N, 3)  (or ``position`` (N, 2) with input="position")
    detected : out, (N,) bool
        The agent senses at least one (active) target.
    target : out, (N,) int64
        Index of the nearest detected target, -1 if none.
    found : out, (M,) bool (not per agent)
        Targets detected by someone so far (latched), including now.

    State
    -----
    found : discrete (M,) bool, updated every step (each hit with ``period``).

    Parameters
    ----------
    n : int
    targets : (M, 2) array
        Target positions [m].
    sensing_radius : float or (N,)
        [m].
    target_radius : float or (M,)
        [m] (default 0: point targets).

    pickup : bool
        Found targets are removed: they are no longer detected after the
        step they were found (search-and-pickup). Default False.
    input : "pose" or "position"
    period : float, optional
    capacity : int, optional
        Most targets per search cell (edge ``max R + max r``) for compiled
        runs; default: planned from ``targets`` with headroom 2 at build
        time. A run whose targets (a numeric parameter) crowd a cell beyond
        it is reported as an overflow, never silently cut.
    reach : float, optional
        The largest ``max R + max r`` a compiled run may use (the search's
        cell edge; default the constructor's values). Raise it to vary the
        radii at run time.

    Notes
    -----
    ``targets``, ``sensing_radius`` and ``target_radius`` are numeric
    parameters (shapes as given).

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import TargetDetection
    >>> b = TargetDetection(2, [[1.0, 0.0], [9.0, 9.0]], sensing_radius=1.5,
    ...                     input="position")
    >>> y = b.output(0.0, b.initial_state(), {"position": np.zeros((2, 2))}, np)
    >>> y["detected"].tolist(), y["target"].tolist(), y["found"].tolist()
    ([True, True], [0, 0], [True, False])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "targets": [[10.0, 10.0], [40.0, 40.0]], "sensing_radius": 2.0}

    def __init__(self, n, targets, *, sensing_radius, target_radius=0.0,
                 pickup=False, input="pose", period=None, capacity=None, reach=None):
        super().__init__()
        name = "TargetDetection"
        self.n = n = agent_count(n, name)
        t = np.asarray(targets, dtype=float)
        if t.ndim != 2 or t.shape[1] != 2 or not np.all(np.isfinite(t)):
            raise ParameterError("targets must be an (M, 2) array of positions",
                                 block=name, param="targets", found=t.shape)
        self.declare_parameter("targets", t, unit="m")
        m = len(t)
        R = np.asarray(sensing_radius, dtype=float)
        r = np.asarray(target_radius, dtype=float)
        if R.shape not in ((), (n,)) or np.any(~np.isfinite(R)) or np.any(R < 0):
            raise ParameterError("sensing_radius must be >= 0, scalar or (N,)",
                                 block=name, param="sensing_radius", found=R)
        if r.shape not in ((), (m,)) or np.any(~np.isfinite(r)) or np.any(r < 0):
            raise ParameterError("target_radius must be >= 0, scalar or (M,)",
                                 block=name, param="target_radius", found=r)
        self.declare_parameter("sensing_radius", R, bounds=(0, None), unit="m")
        self.declare_parameter("target_radius", r, bounds=(0, None), unit="m")
        self.pickup = bool(pickup)
        # targets are the searched points (known now): plan the static cells here
        if reach is not None and not float(reach) >= _reach(R, r):
            raise ParameterError("reach must be >= max sensing_radius + max target_radius",
                                 block=name, param="reach", found=reach)
        reach = _reach(R, r) if reach is None else float(reach)
        self.search = NeighborSearch(reach, points="targets", capacity=capacity)
        if m:
            self.search.plan(t)
        self.input = declare_agents_input(self, n, input)
        self.declare_output("detected", (n,), "bool", doc="senses a target")
        self.declare_output("target", (n,), "int64", doc="nearest target, -1 none")
        self.declare_output("found", (m,), "bool", agents=False,
                            doc="targets found so far (latched)")
        self.declare_discrete_state("found", np.zeros(m, dtype=bool), agents=False)
        maybe_periodic(self, period)

    def _detect(self, x, u, xp):
        active = ~x["found"] if self.pickup else None
        return detect_targets(u[self.input], self.targets, self.sensing_radius,
                              self.target_radius, active, xp=xp, search=self.search)

    def output(self, t, x, u, xp):
        best, seen = self._detect(x, u, xp)
        return {"detected": best >= 0, "target": best, "found": x["found"] | seen}

    def update(self, t, x, u, xp):
        _, seen = self._detect(x, u, xp)
        return {"found": x["found"] | seen}
