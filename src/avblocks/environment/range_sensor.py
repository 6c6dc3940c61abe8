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
actually in range, never N x all segments. Every candidate pair is then
intersected with all its rays at once in NumPy.

NumPy/shapely side computation: not JAX-traceable.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core import rng as _rng
from ..core.block import Block
from ..core.errors import ParameterError
from ._common import agent_count, declare_agents_input, maybe_periodic
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


def _reduce_min(out, rows, vals):
    """out[rows[p]] = min(out[rows[p]], vals[p]) for all p (vectorized)."""
    if len(rows) == 0:
        return
    order = np.argsort(rows, kind="stable")
    rows, vals = rows[order], vals[order]
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    red = np.minimum.reduceat(vals, starts, axis=0)
    u = rows[starts]
    out[u] = np.minimum(out[u], red)


def _ray_segment(o, d, seg):
    """Hit distances (P, R) of rays from o (P, 2) with dirs d (P, R, 2) on seg (P, 4)."""
    a = seg[:, None, :2]
    e = (seg[:, 2:] - seg[:, :2])[:, None, :]
    ao = a - o[:, None, :]
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ao[..., 0] * e[..., 1] - ao[..., 1] * e[..., 0]) / den
        s = (ao[..., 0] * d[..., 1] - ao[..., 1] * d[..., 0]) / den
    ok = (np.abs(den) > _EPS) & (t >= 0) & (s >= -_EPS) & (s <= 1 + _EPS)
    return np.where(ok, t, np.inf)


def _ray_circle(o, d, c, r):
    """Hit distances (P, R) of rays from o (P, 2), dirs d (P, R, 2) on circles c (P, 2), r (P,)."""
    f = (c - o)[:, None, :]
    tca = f[..., 0] * d[..., 0] + f[..., 1] * d[..., 1]
    d2 = np.sum(f * f, axis=-1) - tca**2
    r2 = (r**2)[:, None]
    thc = np.sqrt(np.maximum(r2 - d2, 0.0))
    inside = np.sum(f * f, axis=-1) <= r2
    t = np.where(inside, 0.0, tca - thc)
    ok = inside | ((d2 <= r2) & (tca - thc >= 0))
    return np.where(ok, t, np.inf)


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
    """
    pose = np.asarray(pose, dtype=float)
    n = pose.shape[0]
    angles = np.asarray(angles, dtype=float)
    o = pose[:, :2]
    th = pose[:, 2] if pose.shape[1] >= 3 else np.zeros(n)
    phi = th[:, None] + angles[None, :]
    dirs = np.stack([np.cos(phi), np.sin(phi)], axis=-1)  # (N, R, 2)
    out = np.full((n, len(angles)), float(max_range))
    if world is not None and world.n_obstacles:
        import shapely
        boxes = shapely.box(o[:, 0] - max_range, o[:, 1] - max_range,
                            o[:, 0] + max_range, o[:, 1] + max_range)
        a, g = world.ray_tree.query(boxes)
        ns = len(world.segments)
        seg = g < ns
        if np.any(seg):
            aa = a[seg]
            _reduce_min(out, aa, _ray_segment(o[aa], dirs[aa], world.segments[g[seg]]))
        if np.any(~seg):
            aa, cid = a[~seg], world.circle_ids[g[~seg] - ns]
            t = _ray_circle(o[aa], dirs[aa], world.circle_center[cid],
                            world.circle_radius[cid])
            _reduce_min(out, aa, t)
    if agent_radius is not None and n > 1:
        r = np.broadcast_to(np.asarray(agent_radius, dtype=float), (n,))
        pairs = cKDTree(o).query_pairs(max_range + r.max(), output_type="ndarray")
        if len(pairs):
            i = np.concatenate([pairs[:, 0], pairs[:, 1]])
            j = np.concatenate([pairs[:, 1], pairs[:, 0]])
            _reduce_min(out, i, _ray_circle(o[i], dirs[i], o[j], r[j]))
    return np.minimum(out, max_range)


class RangeSensor(Block):
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

    def __init__(self, world, n, *, n_rays=32, fov=2 * np.pi, max_range=10.0,
                 noise_std=0.0, agent_radius=None, angles=None, input="pose",
                 period=None):
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
        self.angles = np.asarray(angles, dtype=float).ravel()
        if not (np.isfinite(max_range) and max_range > 0):
            raise ParameterError("max_range must be > 0", block=name,
                                 param="max_range", found=max_range)
        if not (np.isfinite(noise_std) and noise_std >= 0):
            raise ParameterError("noise_std must be >= 0", block=name,
                                 param="noise_std", found=noise_std)
        self.max_range, self.noise_std = float(max_range), float(noise_std)
        if agent_radius is not None:
            r = np.asarray(agent_radius, dtype=float)
            if r.shape not in ((), (n,)) or np.any(r < 0):
                raise ParameterError("agent_radius must be >= 0, scalar or (N,)",
                                     block=name, param="agent_radius", found=r.shape)
        self.agent_radius = agent_radius
        self.input = declare_agents_input(self, n, input)
        self.declare_output("ranges", (n, len(self.angles)), unit="m",
                            doc="range along each ray")
        if self.noise_std > 0:
            self.declare_random_state("key")
        maybe_periodic(self, period)

    def output(self, t, x, u, xp):
        r = cast_rays(self.world, np.asarray(u[self.input]), self.angles,
                      self.max_range, self.agent_radius)
        if self.noise_std > 0:
            _, sub = _rng.split(x["key"], np)
            noisy = r + _rng.normal(sub, r.shape, np, 0.0, self.noise_std)
            r = np.where(r < self.max_range, np.clip(noisy, 0.0, self.max_range), r)
        return {"ranges": r}

    def update(self, t, x, u, xp):
        key, _ = _rng.split(x["key"], np)
        return {"key": key}
