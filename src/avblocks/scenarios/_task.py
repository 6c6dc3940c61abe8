"""Pieces the learning-task scenarios (spread, pursuit, navigation) share.

Each task scenario builds its diagram around a vehicle block whose command
comes from one of three places (``controller=``):

- ``"scripted"``: the scenario's hand-written law (what ``avblocks run``
  shows);
- ``"action"``: an :class:`~avblocks.blocks.Action` block named ``action``
  (what :mod:`avblocks.rl` steps; actions in ``[-1, 1]`` per component);
- a path to a ``.npz`` policy (:class:`~avblocks.controllers.Policy`): the
  trained network reading the task block's ``obs``.

and a task block (``task``) computes, with ``xp``, the per-agent
observation ``obs``, the ``reward``, the per-agent ``done`` flag and the
``success`` measure from the vehicles' outputs, so a plain run logs the
same numbers an environment returns.
"""

from __future__ import annotations

import numpy as np


def others_index(n):
    """(n, n-1) int array: for agent i, the indices of the other agents."""
    if n < 2:
        return np.zeros((max(n, 1), 0), dtype=int)
    j = np.arange(n - 1)[None, :]
    return j + (j >= np.arange(n)[:, None])          # skip column i in row i


def pairwise(p, xp):
    """(n, n) distances between the rows of p (n, 2); diagonal = +inf."""
    d = p[:, None, :] - p[None, :, :]
    r = xp.sqrt(xp.sum(d * d, axis=-1) + 1e-12)
    n = p.shape[0]
    return xp.where(np.eye(n, dtype=bool), xp.inf, r)


def uniform_points(key, n, half, xp, min_sep=0.0, tries=8):
    """``n`` points uniform in ``[-half, half]^2`` (rng keys; both engines).
    With ``min_sep`` the draw is repeated ``tries`` times and the candidate
    with the largest closest-pair distance is kept (no loop on values, so
    it traces)."""
    from avblocks.core import rng
    ks = rng.split(key, xp, tries)
    best, best_d = None, None
    for k in ks:
        p = rng.uniform(k, (n, 2), xp, -half, half)
        if min_sep <= 0 or n < 2:
            return p
        d = xp.min(pairwise(p, xp))
        if best is None:
            best, best_d = p, d
        else:
            better = d > best_d
            best = xp.where(better, p, best)
            best_d = xp.where(better, d, best_d)
    return best


def drive_at_speed(d, cmd, velocity, speed):
    """Wire ``cmd`` (unit commands) through a ``speed`` gain into the
    vehicles' ``velocity`` input: the last link of every task scenario."""
    from avblocks.blocks import Gain
    gain = d.add(Gain(float(speed)), name="speed")
    d.connect(cmd, gain.u)
    d.connect(gain.y, velocity)


def command_source(d, controller, n, obs_ref, name="action"):
    """The block that drives the vehicles: Action or a trained Policy."""
    from avblocks.blocks import Action
    if controller == "action":
        return d.add(Action(n, 2, low=-1.0, high=1.0), name=name), "action"
    from avblocks.controllers import Policy
    pol = d.add(Policy.load(str(controller)), name="policy")
    d.connect(obs_ref, pol.obs)
    return pol, "cmd"


# ------------------------------------------------------------ xp geometry
# Obstacles are polygons given as an (E, 4) array of edges (x1, y1, x2, y2);
# the arena is the square [-half, half]^2. Written with ``xp`` so both
# engines (and gradients) run them; checked against shapely in the tests.

def polygon_edges(polygons):
    """(E, 4) edges of closed polygons (each an (V, 2) vertex list)."""
    out = []
    for poly in polygons:
        v = np.asarray(poly, dtype=float)
        out.append(np.concatenate([v, np.roll(v, -1, axis=0)], axis=1))
    return np.concatenate(out, axis=0) if out else np.zeros((0, 4))


def rectangle(cx, cy, w, h):
    """Vertices of an axis-aligned rectangle (counter-clockwise)."""
    return np.array([[cx - w / 2, cy - h / 2], [cx + w / 2, cy - h / 2],
                     [cx + w / 2, cy + h / 2], [cx - w / 2, cy + h / 2]])


def segment_distance(p, edges, xp):
    """(..., E) distance from points p (..., 2) to every edge."""
    a, b = edges[:, :2], edges[:, 2:]
    ab = b - a
    ap = p[..., None, :] - a
    s = xp.clip(xp.sum(ap * ab, -1) / xp.maximum(xp.sum(ab * ab, -1), 1e-12), 0.0, 1.0)
    d = ap - s[..., None] * ab
    return xp.sqrt(xp.sum(d * d, -1) + 1e-12)


def inside(p, edges, xp):
    """(...,) bool: p inside an obstacle (crossing-number parity over all
    edges; obstacles must not overlap)."""
    x, y = p[..., 0:1], p[..., 1:2]
    x1, y1, x2, y2 = edges[:, 0], edges[:, 1], edges[:, 2], edges[:, 3]
    straddle = (y1 > y) != (y2 > y)
    dy = xp.where(y2 == y1, 1.0, y2 - y1)
    xc = x1 + (y - y1) * (x2 - x1) / dy
    cross = straddle & (x < xc)
    return (xp.sum(cross, axis=-1) % 2) == 1


def ray_ranges(p, angles, edges, half, discs, disc_r, max_range, xp, skip_self=True):
    """(n, R) range readings of rays from p (n, 2) at ``angles`` (R,) [rad,
    world frame]: the first hit among obstacle edges, the arena walls and
    other agents' discs (centres ``discs`` (n, 2), radius ``disc_r``),
    capped at ``max_range``."""
    c, s = xp.cos(angles), xp.sin(angles)
    d = xp.stack([c, s], axis=-1)                              # (R, 2)
    big = 1e6
    # obstacle edges: o + t d = a + u e
    a, e = edges[:, :2], edges[:, 2:] - edges[:, :2]          # (E, 2)
    ao = a[None, :, :] - p[:, None, :]                         # (n, E, 2)
    den = d[:, 0][:, None] * e[:, 1][None] - d[:, 1][:, None] * e[:, 0][None]   # (R, E)
    safe = xp.where(xp.abs(den) < 1e-12, 1e-12, den)
    t = (ao[:, None, :, 0] * e[None, None, :, 1] - ao[:, None, :, 1] * e[None, None, :, 0]) \
        / safe[None]                                           # (n, R, E)
    u = (ao[:, None, :, 0] * d[None, :, None, 1] - ao[:, None, :, 1] * d[None, :, None, 0]) \
        / safe[None]
    ok = (xp.abs(den)[None] >= 1e-12) & (t >= 0) & (u >= 0) & (u <= 1)
    t_edge = xp.min(xp.where(ok, t, big), axis=-1) if edges.shape[0] else \
        xp.full((p.shape[0], angles.shape[0]), big)
    # walls x = +-half, y = +-half
    tw = []
    for k in (0, 1):
        dk = d[:, k][None]                                     # (1, R)
        pk = p[:, k][:, None]                                  # (n, 1)
        dks = xp.where(xp.abs(dk) < 1e-12, 1e-12, dk)
        tt = (xp.where(dk > 0, half, -half) - pk) / dks
        tw.append(xp.where(xp.abs(dk) < 1e-12, big, xp.maximum(tt, 0.0)))
    t_wall = xp.minimum(tw[0], tw[1])
    # other agents' discs
    oc = discs[None, :, :] - p[:, None, :]                     # (n, m, 2)
    proj = xp.einsum("nmk,rk->nrm", oc, d)                     # (n, R, m)
    c2 = xp.sum(oc * oc, -1)[:, None, :] - proj * proj
    disc = disc_r * disc_r - c2
    th = proj - xp.sqrt(xp.maximum(disc, 1e-12))       # (no inf gradient at 0)
    hit = (disc >= 0) & (th >= 0)
    if skip_self:
        n = p.shape[0]
        hit = hit & ~np.eye(n, dtype=bool)[:, None, :]
    t_disc = xp.min(xp.where(hit, th, big), axis=-1)
    return xp.minimum(xp.minimum(xp.minimum(t_edge, t_wall), t_disc), max_range)


def free_points(key, n, half, edges, clearance, xp, tries=24, min_sep=0.0):
    """``n`` points uniform in the arena at least ``clearance`` from every
    obstacle and wall and (best effort) ``min_sep`` apart: ``tries``
    candidates per point, the first that fits is kept (traceable)."""
    from avblocks.core import rng
    c = rng.uniform(key, (tries, n, 2), xp, -(half - clearance), half - clearance)
    ok = ~inside(c, edges, xp)
    if edges.shape[0]:
        ok = ok & (xp.min(segment_distance(c, edges, xp), axis=-1) >= clearance)
    if min_sep <= 0 or n < 2:
        pick = xp.argmax(ok, axis=0)                            # first valid (or 0)
        return xp.take_along_axis(c, pick[None, :, None], axis=0)[0]
    # separation: agents pick in turn, each the first candidate that fits
    # the obstacles and the agents before it (n is small: reset only)
    chosen = []
    for i in range(n):
        oki = ok[:, i]
        for q in chosen:
            oki = oki & (xp.sum((c[:, i] - q) ** 2, -1) >= min_sep ** 2)
        chosen.append(c[xp.argmax(oki), i])
    return xp.stack(chosen)
