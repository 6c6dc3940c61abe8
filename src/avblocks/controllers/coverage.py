r"""Coverage control: Lloyd's algorithm on Voronoi cells in a convex polygon.

Equations
---------
For agents at ``p_i`` in a convex polygon ``Q`` with Voronoi cells ``V_i``
(clipped to ``Q``), uniform density, the coverage cost (locational
optimisation function) is

.. math::  H(P) = \sum_i \int_{V_i} \|q - p_i\|^2 \, dq

with gradient ``dH/dp_i = 2 M_i (p_i - C_i)`` (``M_i`` the area, ``C_i`` the
centroid of ``V_i``). The continuous-time Lloyd law

.. math::  \dot p_i = u_i = K (C_i - p_i)

gives ``dH/dt = -2 K sum_i M_i |p_i - C_i|^2 <= 0``: H decreases
monotonically and the agents converge to a centroidal Voronoi configuration.

Cells are computed with :func:`shapely.voronoi_polygons` (clipped to ``Q``),
area, centroid and second moment in closed form from the cell vertices
(``int_V |q|^2 dq = 1/12 sum_k cross_k (x_k^2 + x_k x_{k+1} + x_{k+1}^2 +
y_k^2 + y_k y_{k+1} + y_{k+1}^2)``). NumPy + shapely only (not traceable by
JAX); cost O(N log N) per evaluation. Agents must be at distinct positions
inside ``Q``.

Reference: J. Cortes, S. Martinez, T. Karatas & F. Bullo, "Coverage control
for mobile sensing networks", IEEE TRA 20(2), 2004; S. Lloyd, "Least squares
quantization in PCM", IEEE TIT 28(2), 1982.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar
from .random_walk import convex_halfplanes


def voronoi_cells(points, polygon):
    """Shapely polygons (N,) of the Voronoi cells of ``points`` clipped to ``polygon``."""
    import shapely
    pts = np.asarray(points, dtype=float)
    q = shapely.Polygon(np.asarray(polygon, dtype=float))
    if len(pts) == 1:
        return np.array([q], dtype=object)
    mp = shapely.MultiPoint(pts)
    try:
        cells = shapely.get_parts(shapely.voronoi_polygons(mp, extend_to=q, ordered=True))
    except TypeError:                                 # shapely < 2.1: match by point
        cells = shapely.get_parts(shapely.voronoi_polygons(mp, extend_to=q))
        tree = shapely.STRtree(cells)
        pi, ci = tree.query(shapely.points(pts), predicate="intersects")
        order = np.empty(len(pts), dtype=np.int64)
        order[pi] = ci
        cells = cells[order]
    return shapely.intersection(cells, q)


def cell_moments(points, polygon):
    """Areas (N,), centroids (N, 2) and costs ``int_{V_i} |q - p_i|^2`` (N,)."""
    import shapely
    pts = np.asarray(points, dtype=float)
    n = len(pts)
    cells = voronoi_cells(pts, polygon)
    rings = shapely.get_exterior_ring(cells)
    xy, ind = shapely.get_coordinates(rings, return_index=True)
    same = ind[:-1] == ind[1:]
    a, b, k = xy[:-1][same], xy[1:][same], ind[:-1][same]
    cross = a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]
    area = np.bincount(k, cross, n) / 2
    mx = np.bincount(k, cross * (a[:, 0] + b[:, 0]), n) / 6
    my = np.bincount(k, cross * (a[:, 1] + b[:, 1]), n) / 6
    j0 = np.bincount(k, cross * (a[:, 0] ** 2 + a[:, 0] * b[:, 0] + b[:, 0] ** 2
                                 + a[:, 1] ** 2 + a[:, 1] * b[:, 1] + b[:, 1] ** 2), n) / 12
    sgn = np.where(area < 0, -1.0, 1.0)
    area, mx, my, j0 = area * sgn, mx * sgn, my * sgn, j0 * sgn
    safe = np.where(area > 0, area, 1.0)
    cen = np.where((area > 0)[:, None], np.stack([mx, my], axis=-1) / safe[:, None], pts)
    cost = j0 - 2 * (pts[:, 0] * mx + pts[:, 1] * my) + area * np.sum(pts * pts, axis=1)
    return area, cen, cost


def coverage_cost(points, polygon):
    """The coverage cost ``H(P) = sum_i int_{V_i} |q - p_i|^2 dq`` (uniform density)."""
    return float(np.sum(cell_moments(points, polygon)[2]))


def lloyd_velocity(points, polygon, gain=1.0):
    """``K (C_i - p_i)`` and the centroids (N, 2)."""
    _, cen, _ = cell_moments(points, polygon)
    return gain * (cen - np.asarray(points, dtype=float)), cen


class Coverage(Block):
    """Centroid-seeking (Lloyd) coverage of a convex polygon by N agents.

    Ports
    -----
    position : in, (N, 2).
    velocity : out, (N, 2) — ``K (C_i - p_i)``.
    centroid : out, (N, 2) — centroids of the Voronoi cells.
    cost : out, () — the coverage cost H.

    Parameters
    ----------
    n : int;  polygon : (M, 2) convex;  gain : float > 0.
    period : float, optional — make the block discrete (recompute cells at
        this period and hold), instead of at every solver stage.

    ``gain`` is a numeric parameter; the polygon is structural.

    NumPy + shapely only. Equations, references: module docstring.
    """

    #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
    traceable = False

    def __init__(self, n, polygon, *, gain=1.0, period=None):
        super().__init__()
        self.n = n = int(n)
        if n < 1:
            raise ParameterError("need n >= 1", block="Coverage", param="n", found=n)
        convex_halfplanes(polygon, "Coverage")          # validates convexity
        self.polygon = np.asarray(polygon, dtype=float)
        self.declare_parameter("gain", positive_scalar(gain, "Coverage", "gain"),
                               bounds=(1e-12, None), unit="1/s")
        if period is not None:
            self.declare_periodic(period)
        self.declare_input("position", (n, 2), unit="m")
        self.declare_output("velocity", (n, 2), unit="m/s")
        self.declare_output("centroid", (n, 2), unit="m")
        self.declare_output("cost", (), unit="m^4", agents=False)

    def output(self, t, x, u, xp):
        p = np.asarray(u["position"])
        _, cen, cost = cell_moments(p, self.polygon)
        return {"velocity": xp.asarray(self.gain * (cen - p)),
                "centroid": xp.asarray(cen), "cost": xp.asarray(np.sum(cost))}
