"""Target detection for search and pickup: agents find point targets.

Agent ``i`` detects target ``j`` when ``|p_i - q_j| <= R_i + r_j`` (sensing
radius ``R_i`` of the agent, radius ``r_j`` of the target). Candidate pairs
come from one k-d tree query (``sparse_distance_matrix``), so the cost is
~ (N + M) log M plus the pairs in range. NumPy/SciPy: not JAX-traceable.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core.block import Block
from ..core.errors import ParameterError
from ._common import agent_count, declare_agents_input, maybe_periodic


def detect_targets(pos, targets, sensing_radius, target_radius, active=None):
    """Nearest detected target per agent.

    Returns ``target`` (N,) int64 (index of the nearest detected target,
    -1 if none) and ``hits`` (M,) bool (targets seen by at least one agent).
    Targets with ``active[j]`` false are ignored.
    """
    pos = np.asarray(pos, dtype=float)[:, :2]
    targets = np.asarray(targets, dtype=float)
    n, m = len(pos), len(targets)
    R = np.broadcast_to(np.asarray(sensing_radius, float), (n,))
    r = np.broadcast_to(np.asarray(target_radius, float), (m,))
    best = np.full(n, -1, dtype=np.int64)
    seen = np.zeros(m, dtype=bool)
    if n == 0 or m == 0:
        return best, seen
    sdm = cKDTree(pos).sparse_distance_matrix(cKDTree(targets), R.max() + r.max(),
                                              output_type="ndarray")
    i, j, d = sdm["i"].astype(np.int64), sdm["j"].astype(np.int64), sdm["v"]
    ok = d <= R[i] + r[j]
    if active is not None:
        ok &= np.asarray(active, dtype=bool)[j]
    i, j, d = i[ok], j[ok], d[ok]
    seen[j] = True
    order = np.lexsort((j, d, i))  # by agent, then distance, then target index
    i, j = i[order], j[order]
    first = np.r_[True, i[1:] != i[:-1]] if len(i) else np.zeros(0, bool)
    best[i[first]] = j[first]
    return best, seen


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

    ``targets``, ``sensing_radius`` and ``target_radius`` are numeric
    parameters (shapes as given).

    pickup : bool
        Found targets are removed: they are no longer detected after the
        step they were found (search-and-pickup). Default False.
    input : "pose" or "position"
    period : float, optional

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

    #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
    traceable = False

    def __init__(self, n, targets, *, sensing_radius, target_radius=0.0,
                 pickup=False, input="pose", period=None):
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
        self.input = declare_agents_input(self, n, input)
        self.declare_output("detected", (n,), "bool", doc="senses a target")
        self.declare_output("target", (n,), "int64", doc="nearest target, -1 none")
        self.declare_output("found", (m,), "bool", agents=False,
                            doc="targets found so far (latched)")
        self.declare_discrete_state("found", np.zeros(m, dtype=bool), agents=False)
        maybe_periodic(self, period)

    def _detect(self, x, u):
        active = ~x["found"] if self.pickup else None
        return detect_targets(u[self.input], self.targets, self.sensing_radius,
                              self.target_radius, active)

    def output(self, t, x, u, xp):
        best, seen = self._detect(x, u)
        return {"detected": best >= 0, "target": best, "found": x["found"] | seen}

    def update(self, t, x, u, xp):
        _, seen = self._detect(x, u)
        return {"found": x["found"] | seen}
