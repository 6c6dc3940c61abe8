"""Lidar-like range sensing: rays from each agent against obstacle edges,
circles and other agents' discs.

Vectorized ray casting
----------------------
Ray ``o + t d`` (``|d| = 1``, ``t >= 0``) against segment ``a + s e``,
``s in [0, 1]``::

    t = ((a - o) x e) / (d x e),   s = ((a - o) x d) / (d x e)

against a circle (centre ``c``, radius ``r``), with ``f = c - o``::

    t = f.d - sqrt(r^2 - (|f|^2 - (f.d)^2))     (0 when o is inside)

Broad phase: one shapely ``STRtree`` query of every agent's sensing box
against the boxes of all edges and circles (``World.ray_tree``) and one
k-d tree pair query between agents, so the work is ~ N log N plus the pairs
actually in range, never N x all segments. Each candidate pair is then
intersected only with the rays inside the arc of directions it subtends
(found by a binary search in the sorted ray angles), all in flat NumPy
arrays.

That is :func:`cast_rays`, the NumPy/shapely method
(``RangeSensor(..., method="shapely")``).

Traceable method (``method="grid"``; the default ``"auto"`` uses it when compiled)
-----------------------------------------------------------------------------------
:func:`cast_rays_grid` uses the same two hit formulas in ``xp`` code with
static shapes: the world's edges and circles as padded arrays with a
uniform-grid broad phase (:class:`~avblocks.environment.edges.EdgeGrid`
built for ``reach = max_range``: an agent's cell lists every edge and
circle within ``max_range`` of any point of the cell, ``K`` and ``Kc`` of
them at most), so each agent intersects its R rays with its own
candidates only, an (N, K, R) product (no angular culling: every ray
tests every candidate). A small world (the grid's ``dense``) is tested
whole instead, its axis-aligned rectangles and walls as boxes by the slab
method (:func:`~avblocks.environment.boxes.ray_boxes`: one expression per
box, not four edges); so is every edge when a cell keeps more than half
of them. The fan of rays is turned by each agent's heading with one sin
and cos per agent. Other agents come from a
:class:`~avblocks.utility.spatial.NeighborSearch` within ``max_range +
max(agent_radius)``: (N, M, R). Both methods agree to 1e-9 m (tests).

The default, ``method="auto"``, is traceable: a compiled run uses the grid
method and the NumPy engine :func:`cast_rays`, the faster there (it culls
rays by the arc each edge subtends): 32 rays, 8 m, 200 random obstacles,
one agent per 16 m^2: 3.3 / 11 / 75 ms at N = 100 / 1,000 / 10,000 against
29 / 178 / 2,600 ms for the grid code in NumPy (2 cores).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ..core import rng as _rng
from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar
from ..utility.arrays import fold
from ..utility.spatial import Need, NeighborSearch
from ._common import (
    SMALL_N,
    EdgeGridOwner,
    agent_count,
    all_pairs,
    declare_agents_input,
    maybe_periodic,
)
from .boxes import inverse_direction, ray_boxes
from .edges import ray_circle, ray_segment
from .world import World

_EPS = 1e-12


def ray_angles(n_rays, fov=2 * np.pi):
    """Ray directions relative to the heading: evenly spread over ``fov``.

    Full circle (``fov >= 2 pi``): ``2 pi k / n`` (ray 0 straight ahead).
    Otherwise from ``-fov/2`` to ``+fov/2`` inclusive (one ray: straight ahead).
    """
    n_rays = int(n_rays)
    if fov >= 2 * np.pi - 1e-12:
        return 2 * np.pi * np.arange(n_rays) / n_rays
    if n_rays == 1:
        return np.zeros(1)
    return np.linspace(-fov / 2, fov / 2, n_rays)


def _ray_segment(ox, oy, cs, sn, seg):
    """Hit distance of rays (origin ox, oy; direction cs, sn) on segments
    ``seg`` (..., 4); all arguments broadcast element-wise; inf on a miss."""
    ex, ey = seg[..., 2] - seg[..., 0], seg[..., 3] - seg[..., 1]
    ax, ay = seg[..., 0] - ox, seg[..., 1] - oy
    den = cs * ey - sn * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / den
        t = (ax * ey - ay * ex) * inv
        u = (ax * sn - ay * cs) * inv
    ok = (np.abs(den) > _EPS) & (t >= 0) & (u >= -_EPS) & (u <= 1 + _EPS)
    return np.where(ok, t, np.inf)


def _ray_circle(ox, oy, cs, sn, cx, cy, r):
    """Hit distance of rays on circles (centre cx, cy, radius r), element-wise;
    0 when the origin is inside, inf on a miss."""
    fx, fy = cx - ox, cy - oy
    tca = fx * cs + fy * sn
    ff = fx * fx + fy * fy
    d2 = ff - tca * tca
    r2 = r * r
    thc = np.sqrt(np.maximum(r2 - d2, 0.0))
    inside = ff <= r2
    ok = inside | ((d2 <= r2) & (tca - thc >= 0))
    return np.where(ok, np.where(inside, 0.0, tca - thc), np.inf)


class _Rays:
    """Ray bookkeeping: which rays of an agent fall in an angular interval."""

    def __init__(self, angles, heading):
        self.R = R = len(angles)
        rel = np.mod(angles, 2 * np.pi)
        self.perm = np.argsort(rel, kind="stable")
        srt = rel[self.perm]
        self.sorted2 = np.concatenate([srt, srt + 2 * np.pi])
        self.heading = heading
        phi = heading[:, None] + angles[None, :]
        self.cs, self.sn = np.cos(phi), np.sin(phi)
        self.R = R

    def candidates(self, agent, lo, span):
        """(pair index, ray index) of rays of ``agent[p]`` whose direction lies
        in the arc ``[lo[p], lo[p] + span[p]]`` (absolute angles)."""
        R = self.R
        start = np.mod(lo - self.heading[agent] - _ARC_EPS, 2 * np.pi)
        k0 = np.searchsorted(self.sorted2, start, side="left")
        k1 = np.searchsorted(self.sorted2, start + span + 2 * _ARC_EPS, side="right")
        cnt = np.minimum(k1 - k0, R)
        total = int(cnt.sum())
        pair = np.repeat(np.arange(len(agent)), cnt)
        off = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ray = self.perm[(k0[pair] + off) % R]
        return pair, ray


_ARC_EPS = 1e-9


def _reduce_min_flat(out, flat, vals):
    """out.flat[flat[p]] = min(out.flat[flat[p]], vals[p]) (vectorized)."""
    if len(flat) == 0:
        return
    o = out.reshape(-1)
    order = np.argsort(flat, kind="stable")
    flat, vals = flat[order], vals[order]
    starts = np.flatnonzero(np.r_[True, flat[1:] != flat[:-1]])
    u = flat[starts]
    o[u] = np.minimum(o[u], np.minimum.reduceat(vals, starts))


def _circle_arcs(ox, oy, cx, cy, r):
    """Start angle and span of the arc of directions that can hit a circle."""
    fx, fy = cx - ox, cy - oy
    d = np.hypot(fx, fy)
    half = np.arcsin(np.clip(r / np.maximum(d, 1e-300), 0.0, 1.0))
    full = d <= r
    lo = np.where(full, 0.0, np.arctan2(fy, fx) - half)
    span = np.where(full, 2 * np.pi, 2 * half)
    return lo, span


def _segment_arcs(ox, oy, seg):
    """Start angle and span of the directions from (ox, oy) that meet a segment."""
    ax, ay = seg[:, 0] - ox, seg[:, 1] - oy
    bx, by = seg[:, 2] - ox, seg[:, 3] - oy
    cross = ax * by - ay * bx
    dot = ax * bx + ay * by
    span = np.arctan2(np.abs(cross), dot)
    lo = np.where(cross >= 0, np.arctan2(ay, ax), np.arctan2(by, bx))
    full = (span > np.pi - 1e-6) | (np.hypot(ax, ay) < 1e-12) | (np.hypot(bx, by) < 1e-12)
    return np.where(full, 0.0, lo), np.where(full, 2 * np.pi, span)


def cast_rays(world, pose, angles, max_range, agent_radius=None):
    """Ranges (N, R) seen by N agents along rays at ``angles`` from their headings.

    Parameters
    ----------
    world : World or None
    pose : (N, 3) poses (or (N, 2): heading 0)
    angles : (R,) ray angles relative to the heading [rad]
    max_range : float
        Rays that hit nothing within it return ``max_range``.
    agent_radius : float or (N,), optional
        Other agents seen as discs of this radius (None: agents invisible).
        An agent never sees its own disc.

    Each candidate (agent, edge/circle/agent) pair from the broad phase is
    intersected only with the rays whose directions fall in the arc the
    edge or circle subtends from the agent (a sorted-angle search), so the
    narrow phase costs ~ pairs x (rays per arc), not pairs x all rays.
    """
    pose = np.asarray(pose, dtype=float)
    n = pose.shape[0]
    angles = np.asarray(angles, dtype=float).ravel()
    R = len(angles)
    o = pose[:, :2]
    th = pose[:, 2] if pose.shape[1] >= 3 else np.zeros(n)
    rays = _Rays(angles, th)
    out = np.full((n, R), float(max_range))

    def narrow(agent, lo, span, hit_fn):
        p, k = rays.candidates(agent, lo, span)
        ag = agent[p]
        t = hit_fn(p, ag, rays.cs[ag, k], rays.sn[ag, k])
        _reduce_min_flat(out, ag * R + k, t)

    if world is not None and world.n_obstacles:
        import shapely
        boxes = shapely.box(o[:, 0] - max_range, o[:, 1] - max_range,
                            o[:, 0] + max_range, o[:, 1] + max_range)
        a, g = world.ray_tree.query(boxes)
        ns = len(world.segments)
        seg = g < ns
        if np.any(seg):
            aa, sg = a[seg], world.segments[g[seg]]
            lo, span = _segment_arcs(o[aa, 0], o[aa, 1], sg)
            narrow(aa, lo, span, lambda p, ag, c, s_: _ray_segment(
                o[ag, 0], o[ag, 1], c, s_, sg[p]))
        if np.any(~seg):
            aa, cid = a[~seg], world.circle_ids[g[~seg] - ns]
            cc, cr = world.circle_center[cid], world.circle_radius[cid]
            lo, span = _circle_arcs(o[aa, 0], o[aa, 1], cc[:, 0], cc[:, 1], cr)
            narrow(aa, lo, span, lambda p, ag, c, s_: _ray_circle(
                o[ag, 0], o[ag, 1], c, s_, cc[p, 0], cc[p, 1], cr[p]))
    if agent_radius is not None and n > 1:
        r = np.broadcast_to(np.asarray(agent_radius, dtype=float), (n,))
        pairs = cKDTree(o).query_pairs(max_range + r.max(), output_type="ndarray")
        if len(pairs):
            i = np.concatenate([pairs[:, 0], pairs[:, 1]])
            j = np.concatenate([pairs[:, 1], pairs[:, 0]])
            lo, span = _circle_arcs(o[i, 0], o[i, 1], o[j, 0], o[j, 1], r[j])
            narrow(i, lo, span, lambda p, ag, c, s_: _ray_circle(
                o[ag, 0], o[ag, 1], c, s_, o[j[p], 0], o[j[p], 1], r[j[p]]))
    return np.minimum(out, max_range)


def _all_edges(grid):
    """Test every edge rather than the cell's candidates: when a cell keeps
    more than half of them the per-agent gathers cost more than the tests
    they save. Exact either way: an edge left out of a cell is farther than
    the grid's reach (>= ``max_range``) from any point of it, so its hits
    are capped to ``max_range``."""
    return 2 * grid.K >= grid.n_edges


def cast_rays_grid(grid, search, pose, angles, max_range, agent_radius=None, xp=np):
    """:func:`cast_rays` in ``xp`` code (traceable), (N, R) ranges.

    ``grid``: an :class:`EdgeGrid` of the world built for reach >=
    ``max_range`` (or None: no world); ``search``: a
    :class:`NeighborSearch` with reach >= ``max_range + max(agent_radius)``
    (used when ``agent_radius`` is given and N > 1).
    """
    n = pose.shape[0]
    # layout (N, items, R): the rays on the last axis, each reduction a
    # fused min (utility.arrays.fold) over the middle one (with XLA's plain
    # min, the items last ran 3.5x slower under vmap on a CPU)
    ox, oy = pose[:, 0:1, None], pose[:, 1:2, None]                     # (N, 1, 1)
    ang = xp.asarray(angles, dtype=pose.dtype)
    ca, sa = xp.cos(ang), xp.sin(ang)                                   # (R,)
    if pose.shape[1] >= 3:          # the fan turned by the heading: one sin/cos per agent
        c, s = xp.cos(pose[:, 2:3]), xp.sin(pose[:, 2:3])
        ux, uy = (c * ca - s * sa)[:, None, :], (s * ca + c * sa)[:, None, :]   # (N, 1, R)
    else:                           # world frame: the same directions for every agent
        ux = xp.broadcast_to(ca, (n, 1, ca.shape[0]))
        uy = xp.broadcast_to(sa, (n, 1, ca.shape[0]))
    rmax = xp.asarray(max_range, dtype=pose.dtype)
    out = xp.full((n, ux.shape[-1]), xp.inf, dtype=pose.dtype)

    def nearest(t, ok=None):                    # (N, items, R) -> (N, R)
        return fold(xp.minimum, t if ok is None else xp.where(ok[..., None], t, xp.inf),
                    -2, xp)

    def col(a):                                 # items on the middle axis
        return xp.asarray(a, dtype=pose.dtype)[..., None]
    if grid is not None and grid.n_edges and (grid.dense or _all_edges(grid)):
        if len(grid.boxes):                     # axis-aligned rectangles: slabs
            b = grid.boxes
            t = ray_boxes(ox, oy, inverse_direction(ux, xp), inverse_direction(uy, xp),
                          col(b[:, 0]), col(b[:, 1]), col(b[:, 2]), col(b[:, 3]), xp)
            out = xp.minimum(out, nearest(t))                            # (N, B, R)
        if len(grid.rest):
            sg = grid.seg[grid.rest]                                     # (E', 2, 2)
            t = ray_segment(ox, oy, ux, uy, col(sg[:, 0, 0]), col(sg[:, 0, 1]),
                            col(sg[:, 1, 0]), col(sg[:, 1, 1]), xp)      # (N, E', R)
            out = xp.minimum(out, nearest(t))
    elif grid is not None and grid.n_edges:
        e, _, _ = grid.candidate_edges(pose[:, :2], xp)
        seg = xp.asarray(grid.seg)[xp.where(e >= 0, e, grid.n_edges)]  # (N, K, 2, 2)
        t = ray_segment(ox, oy, ux, uy, col(seg[..., 0, 0]), col(seg[..., 0, 1]),
                        col(seg[..., 1, 0]), col(seg[..., 1, 1]), xp)    # (N, K, R)
        out = xp.minimum(out, nearest(t, e >= 0))
    if grid is not None and grid.n_circles and grid.dense:
        cen, rad = grid.circle_center[:-1], grid.circle_radius[:-1]
        t = ray_circle(ox, oy, ux, uy, col(cen[:, 0]), col(cen[:, 1]), col(rad), xp)
        out = xp.minimum(out, nearest(t))                                # (N, Mc, R)
    elif grid is not None and grid.n_circles:
        c = grid.candidate_circles(pose[:, :2], xp)
        cc = xp.where(c >= 0, c, grid.n_circles)
        cen = xp.asarray(grid.circle_center)[cc]                        # (N, Kc, 2)
        rad = xp.asarray(grid.circle_radius)[cc]
        t = ray_circle(ox, oy, ux, uy, col(cen[..., 0]), col(cen[..., 1]), col(rad), xp)
        out = xp.minimum(out, nearest(t, c >= 0))
    if agent_radius is not None and n > 1 and search is not None:
        r = xp.broadcast_to(xp.asarray(agent_radius, dtype=pose.dtype), (n,))
        dense = all_pairs(search, pose[:, :2], xp)     # discs past the range: capped
        if dense is not None:                          # column j: agent j (no gather)
            ok = dense[0] >= 0
            cx, cy, rj = pose[None, :, 0], pose[None, :, 1], r[None, :]
        else:
            idx, _ = search.within(pose[:, :2], rmax + xp.max(r), xp=xp)
            ok = idx >= 0
            j = xp.where(ok, idx, 0)
            cx, cy, rj = pose[j, 0], pose[j, 1], r[j]
        t = ray_circle(ox, oy, ux, uy, col(cx), col(cy), col(rj), xp)
        out = xp.minimum(out, nearest(t, ok))                            # (N, M, R)
    return xp.minimum(out, rmax)


class RangeSensor(EdgeGridOwner, Block):
    """A lidar-like range sensor on each of N agents.

    Ports
    -----
    pose : in, (N, 3) [m, m, rad]  (or ``position`` (N, 2): heading 0)
    ranges : out, (N, R) [m]
        Distance to the first obstacle edge, circle or other agent along each
        ray, ``max_range`` when nothing is hit. Ray ``r`` points at
        ``theta + angles[r]`` (see :func:`ray_angles`).

    State
    -----
    key : random key (only with ``noise_std > 0``).

    Parameters
    ----------
    world : World or None
    n : int
    n_rays : int
        ``R`` (default 32).
    fov : float
        Field of view [rad] (default 2 pi, all around).
    max_range : float
        [m] (default 10).
    noise_std : float
        Standard deviation of additive Gaussian noise on rays that hit
        something [m]; noisy values are clipped to ``[0, max_range]``.
    agent_radius : float or (N,), optional
        See other agents as discs of this radius (default: agents invisible).
    angles : (R,) array, optional
        Explicit ray angles (overrides ``n_rays`` and ``fov``).

    input : "pose" or "position"
    period : float, optional
        Discrete block with this period (a scan per hit).
    method : "auto", "grid" or "shapely"
        ``"grid"``: traceable ``xp`` code (:func:`cast_rays_grid`) in both
        engines. ``"shapely"``: the NumPy :func:`cast_rays` (NumPy engine
        only). ``"auto"`` (default): grid when compiled, :func:`cast_rays`
        in the NumPy engine (faster there). They agree to 1e-9 m.
    reach : float, optional
        Largest ``max_range`` the static grid serves (structural; default
        the ``max_range`` given). A larger ``max_range`` set later re-builds
        the grid in the NumPy engine and is reported by a compiled run.
    capacity : int, optional
        Static per-cell capacity of the agent search (compiled engine);
        default: all pairs for ``n <= SMALL_N``, else planned by the engine.

    Notes
    -----
    ``angles`` (the rays, (R,)), ``max_range``, ``noise_std`` and
    ``agent_radius`` (when given) are numeric parameters; ``n_rays`` and
    whether there is noise (a random state) are structural.

    Equations
    ---------
    See :mod:`avblocks.environment.range_sensor`.

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import RangeSensor, World, rectangle
    >>> s = RangeSensor(World([rectangle(2, -5, 3, 5)]), 1, n_rays=4, max_range=10)
    >>> s.output(0.0, s.initial_state(), {"pose": np.zeros((1, 3))}, np)["ranges"].round(6)
    array([[ 2., 10., 10., 10.]])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"world": {"corridor": {"x0": 24.0, "x1": 32.0, "width": 2.0}}, "n": "$agents"}

    def __init__(self, world, n, *, n_rays=32, fov=2 * np.pi, max_range=10.0,
                 noise_std=0.0, agent_radius=None, angles=None, input="pose",
                 period=None, method="auto", reach=None, capacity=None):
        super().__init__()
        name = "RangeSensor"
        if world is not None and not isinstance(world, World):
            raise ParameterError("world must be a World or None", block=name,
                                 param="world", found=type(world).__name__)
        self.world = world
        self.n = n = agent_count(n, name)
        if angles is None:
            n_rays = agent_count(n_rays, name)
            if not (0 < fov <= 2 * np.pi):
                raise ParameterError("fov must lie in (0, 2 pi]", block=name,
                                     param="fov", found=fov)
            angles = ray_angles(n_rays, fov)
        self.declare_parameter("angles", np.asarray(angles, dtype=float).ravel(),
                               unit="rad", doc="ray directions relative to the heading")
        if not (np.isfinite(max_range) and max_range > 0):
            raise ParameterError("max_range must be > 0", block=name,
                                 param="max_range", found=max_range)
        if not (np.isfinite(noise_std) and noise_std >= 0):
            raise ParameterError("noise_std must be >= 0", block=name,
                                 param="noise_std", found=noise_std)
        self.declare_parameter("max_range", float(max_range), bounds=(1e-12, None),
                               unit="m")
        self.declare_parameter("noise_std", float(noise_std), bounds=(0, None), unit="m")
        noisy = float(noise_std) > 0
        if agent_radius is not None:
            r = np.asarray(agent_radius, dtype=float)
            if r.shape not in ((), (n,)) or np.any(r < 0):
                raise ParameterError("agent_radius must be >= 0, scalar or (N,)",
                                     block=name, param="agent_radius", found=r.shape)
            self.declare_parameter("agent_radius", r, bounds=(0, None), unit="m")
        else:
            self.agent_radius = None
        self.input = declare_agents_input(self, n, input)
        self.declare_output("ranges", (n, len(self.angles)), unit="m",
                            doc="range along each ray")
        self._noisy = noisy
        if noisy:
            self.declare_random_state("key")
        maybe_periodic(self, period)
        if method not in ("auto", "grid", "shapely"):
            raise ParameterError("method must be 'auto', 'grid' or 'shapely'", block=name,
                                 param="method", expected=["auto", "grid", "shapely"],
                                 found=method)
        self.method = method
        if method == "shapely":
            #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
            self.traceable = False
            return
        reach = positive_scalar(max_range if reach is None else reach, name, "reach")
        self._grid_cache = {}            # EdgeGrid per reach (a memo: not in the compile key)
        self._reach = reach
        self.search = None
        if agent_radius is not None and n > 1:
            sreach = reach + float(np.max(agent_radius))
            if capacity is None and n <= SMALL_N:
                sreach = math.inf       # all pairs: (N, N), exact, no plan needed
            self.search = NeighborSearch(reach=sreach, points=self.input,
                                         capacity=capacity)

    def output(self, t, x, u, xp):
        if self.method == "shapely" or (self.method == "auto" and xp is np):
            r = cast_rays(self.world, np.asarray(u[self.input]), self.angles,
                          float(self.max_range), self.agent_radius)
            xn = np
        else:
            grid, xn = self.edges, xp
            if grid is not None:
                if xp is np:
                    if float(self.max_range) > grid.reach:
                        grid = self._grid(float(self.max_range))
                else:
                    from ..core import diagnostics
                    diagnostics.report(grid, Need(xp.asarray(0), self.max_range), grid)
            r = cast_rays_grid(grid, self.search, u[self.input], self.angles,
                               self.max_range, self.agent_radius, xp)
        if self._noisy:
            _, sub = _rng.split(x["key"], xn)
            noisy = r + _rng.normal(sub, r.shape, xn, 0.0, self.noise_std)
            r = xn.where(r < self.max_range, xn.clip(noisy, 0.0, self.max_range), r)
        return {"ranges": r}

    def update(self, t, x, u, xp):
        key, _ = _rng.split(x["key"], np if self.method == "shapely" else xp)
        return {"key": key}
