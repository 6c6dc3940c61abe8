"""Random initial positions and poses with a minimum separation.

>>> p = random_poses(20, area=(10.0, 10.0), min_separation=1.0, seed=1)
>>> p.shape
(20, 3)
>>> from scipy.spatial.distance import pdist
>>> bool(pdist(p[:, :2]).min() >= 1.0)
True
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import ParameterError
from .angles import wrap_angle

_HEX_DENSITY = math.pi / (2 * math.sqrt(3))   # densest packing of equal discs


def _region(area):
    """``(bounds, polygon or None)`` of an area given as (w, h), a box or a polygon."""
    import shapely
    from shapely.geometry.base import BaseGeometry

    if isinstance(area, BaseGeometry):
        poly = area
    else:
        try:
            a = np.asarray(area, dtype=float)
        except (TypeError, ValueError):
            raise ParameterError("area must be (w, h), (xmin, xmax, ymin, ymax) or a "
                                 "polygon", param="area", found=repr(area)[:80]) from None
        if a.shape == (2,):
            a = np.array([0.0, a[0], 0.0, a[1]])
        if a.shape == (4,):
            if not (np.all(np.isfinite(a)) and a[1] > a[0] and a[3] > a[2]):
                raise ParameterError("the area box is empty or not finite", param="area",
                                     expected="xmax > xmin and ymax > ymin",
                                     found=tuple(a))
            return (a[0], a[2], a[1], a[3]), None
        if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 3:
            raise ParameterError("area must be (w, h), (xmin, xmax, ymin, ymax) or a "
                                 "polygon's (M, 2) vertices", param="area",
                                 expected="(2,), (4,) or (M>=3, 2)", found=a.shape)
        poly = shapely.Polygon(a)
    if poly.is_empty or not poly.is_valid or poly.area <= 0:
        raise ParameterError("the area polygon is empty or invalid (self-intersecting?)",
                             param="area", found=getattr(poly, "wkt", repr(poly))[:80])
    return poly.bounds, poly


def _generator(seed):
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


def random_positions(n, area=(1.0, 1.0), min_separation=0.0, seed=None, *,
                     max_candidates=None):
    """``n`` uniform random points in ``area``, pairwise at least
    ``min_separation`` apart.

    Parameters
    ----------
    n : int
        Number of points.
    area : (w, h), (xmin, xmax, ymin, ymax), (M, 2) vertices or shapely geometry
        Where to draw: ``(w, h)`` is the box ``[0, w] x [0, h]``.
    min_separation : float
        Smallest allowed distance between two points (0: plain uniform).
    seed : int, numpy Generator or None
        Random source (None: fresh entropy).
    max_candidates : int, optional
        Give up after drawing this many candidate points (default
        ``200 n + 10000``).

    Returns
    -------
    ndarray, shape (n, 2)

    Raises
    ------
    ParameterError
        When the separation cannot be met: at once if even the densest
        packing of discs of diameter ``min_separation`` could not hold ``n``
        points, else when ``max_candidates`` are exhausted.

    Notes
    -----
    Random sequential addition in batches: uniform candidates (rejected
    outside a polygon with ``shapely.contains_xy``) are kept when a k-d tree
    finds no accepted point closer than ``min_separation``; a candidate that
    conflicts with an earlier candidate of its batch is dropped. Random
    sequential addition jams at about 55 % of the area covered by the discs,
    so requests close to that density fail.
    """
    import shapely
    from scipy.spatial import cKDTree

    try:
        n_ok = int(n) == n and n >= 0
    except (TypeError, ValueError):
        n_ok = False
    if not n_ok:
        raise ParameterError("n must be a non-negative integer", param="n",
                             expected="int >= 0", found=n)
    n = int(n)
    try:
        d = float(min_separation)
    except (TypeError, ValueError):
        d = float("nan")
    if not (math.isfinite(d) and d >= 0):
        raise ParameterError("min_separation must be a finite number >= 0",
                             param="min_separation", expected=">= 0", found=min_separation)
    (xmin, ymin, xmax, ymax), poly = _region(area)
    gen = _generator(seed)
    if max_candidates is None:
        max_candidates = 200 * n + 10000
    if n == 0:
        return np.zeros((0, 2))

    def draw(k):
        pts = gen.uniform((xmin, ymin), (xmax, ymax), size=(k, 2))
        if poly is not None:
            pts = pts[shapely.contains_xy(poly, pts[:, 0], pts[:, 1])]
        return pts

    if d == 0:
        out = np.zeros((0, 2))
        drawn = 0
        while len(out) < n and drawn < max_candidates:
            k = 2 * (n - len(out)) + 16
            out = np.concatenate([out, draw(k)])
            drawn += k
        if len(out) < n:
            raise ParameterError("could not draw enough points inside the area",
                                 param="area", found=f"{len(out)} of {n}")
        return out[:n]

    region_area = (poly.buffer(d / 2).area if poly is not None
                   else (xmax - xmin + d) * (ymax - ymin + d))
    if n * math.pi * d * d / 4 > _HEX_DENSITY * region_area:
        raise ParameterError(
            f"{n} points {d} apart cannot fit in the area (not even in the densest "
            "packing)", param="min_separation",
            expected=f"<= {math.sqrt(4 * _HEX_DENSITY * region_area / (math.pi * n)):.4g}",
            found=d, hint="enlarge the area, lower min_separation or place fewer agents")
    acc = np.zeros((0, 2))
    drawn = 0
    while len(acc) < n and drawn < max_candidates:
        k = min(4 * (n - len(acc)) + 64, max_candidates - drawn)
        drawn += k
        cand = draw(k)
        if len(cand) == 0:
            continue
        if len(acc):
            dist, _ = cKDTree(acc).query(cand, k=1)
            cand = cand[dist >= d]
        if len(cand) > 1:
            pairs = cKDTree(cand).query_pairs(r=d, output_type="ndarray")
            if len(pairs):
                keep = np.ones(len(cand), dtype=bool)
                keep[pairs.max(axis=1)] = False
                cand = cand[keep]
        acc = np.concatenate([acc, cand[: n - len(acc)]])
    if len(acc) < n:
        raise ParameterError(
            f"could place only {len(acc)} of {n} points {d} apart after "
            f"{drawn} random candidates", param="min_separation", found=d,
            hint="enlarge the area, lower min_separation or place fewer agents "
                 "(random placement fills at most about half of the area with discs)")
    return acc


def random_poses(n, area=(1.0, 1.0), min_separation=0.0, seed=None, *,
                 max_candidates=None):
    """``n`` random poses ``(x, y, theta)``: positions as in
    :func:`random_positions`, headings uniform in (-pi, pi].

    Returns
    -------
    ndarray, shape (n, 3)
    """
    gen = _generator(seed)
    xy = random_positions(n, area, min_separation, gen, max_candidates=max_candidates)
    th = wrap_angle(gen.uniform(-np.pi, np.pi, size=len(xy)))
    return np.concatenate([xy, th[:, None]], axis=1)


__all__ = ["random_positions", "random_poses"]
