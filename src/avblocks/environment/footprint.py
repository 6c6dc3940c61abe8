"""Agent footprints: the shape of each vehicle used for collisions.

A footprint is given in the body frame (x forward, y left, origin at the
pose's point) and posed by each agent's pose ``(x, y, theta)``.

- :class:`Disc` ``(radius)``: exact discs (scalar or one radius per agent);
- :class:`PolygonFootprint` ``(vertices)``: any simple polygon, the same
  for all agents ``(V, 2)`` or one per agent ``(N, V, 2)``;
- :func:`Rectangle` ``(length, width)``: a centred rectangle polygon.

:func:`default_footprint` gives a footprint per vehicle family.

>>> from avblocks.environment import Rectangle
>>> fp = Rectangle(2.0, 1.0)
>>> fp.posed_coords([[0.0, 0.0, 0.0]])[0].tolist()
[[1.0, -0.5], [1.0, 0.5], [-1.0, 0.5], [-1.0, -0.5]]
"""

from __future__ import annotations

import numpy as np
import shapely

from ..core.errors import ParameterError


class Footprint:
    """Base class of footprints (abstract)."""

    def bounding_radius(self, n):
        """(n,) radius of a disc around the pose point containing the footprint."""
        raise NotImplementedError


class Disc(Footprint):
    """A disc of ``radius`` (scalar or (N,)) centred on the pose point."""

    def __init__(self, radius):
        r = np.asarray(radius, dtype=float)
        if r.ndim > 1 or not np.all(np.isfinite(r)) or not np.all(r >= 0):
            raise ParameterError("disc radius must be >= 0 (scalar or (N,))",
                                 param="radius", found=radius)
        self.radius = r

    def radii(self, n):
        r = self.radius
        if r.ndim == 1 and r.shape[0] != n:
            raise ParameterError("one disc radius per agent expected", param="radius",
                                 expected=(n,), found=r.shape)
        return np.broadcast_to(r, (n,)).astype(float)

    def bounding_radius(self, n):
        return self.radii(n)

    def __repr__(self):
        return f"Disc({self.radius.tolist()})"


class PolygonFootprint(Footprint):
    """A polygon in the body frame: vertices (V, 2), or (N, V, 2) per agent."""

    def __init__(self, vertices):
        v = np.asarray(vertices, dtype=float)
        if v.ndim not in (2, 3) or v.shape[-1] != 2 or v.shape[-2] < 3:
            raise ParameterError("footprint vertices must be (V >= 3, 2) or (N, V, 2)",
                                 param="vertices", found=v.shape)
        if not np.all(np.isfinite(v)):
            raise ParameterError("footprint vertices must be finite", param="vertices")
        if v.ndim == 2 and not shapely.Polygon(v).is_valid:
            raise ParameterError("footprint polygon is not simple (self-intersecting)",
                                 param="vertices")
        self.vertices = v

    def body(self, n):
        v = self.vertices
        if v.ndim == 3 and v.shape[0] != n:
            raise ParameterError("one footprint polygon per agent expected",
                                 param="vertices", expected=(n, "V", 2), found=v.shape)
        return np.broadcast_to(v, (n, *v.shape[-2:]))

    def bounding_radius(self, n):
        return np.linalg.norm(self.body(n), axis=-1).max(axis=-1)

    def posed_coords(self, pose):
        """(N, V, 2) world coordinates of the vertices for poses (N, 3) or (N, 2)."""
        pose = np.asarray(pose, dtype=float)
        n = pose.shape[0]
        v = self.body(n)
        if pose.shape[1] >= 3:
            c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        else:
            c, s = np.ones(n), np.zeros(n)
        x = c[:, None] * v[..., 0] - s[:, None] * v[..., 1] + pose[:, 0:1]
        y = s[:, None] * v[..., 0] + c[:, None] * v[..., 1] + pose[:, 1:2]
        return np.stack([x, y], axis=-1)

    def posed(self, pose):
        """(N,) array of shapely polygons for the given poses."""
        return shapely.polygons(self.posed_coords(pose))

    def __repr__(self):
        return f"PolygonFootprint({self.vertices.shape[-2]} vertices)"


def Rectangle(length, width, center=(0.0, 0.0)):  # noqa: N802 - reads as a shape
    """A ``length`` (along x, forward) by ``width`` rectangle footprint whose
    centre sits at ``center`` in the body frame."""
    if not (length > 0 and width > 0):
        raise ParameterError("rectangle footprint needs length, width > 0",
                             param="length/width", found=(length, width))
    cx, cy = center
    hl, hw = length / 2.0, width / 2.0
    return PolygonFootprint([[cx + hl, cy - hw], [cx + hl, cy + hw],
                             [cx - hl, cy + hw], [cx - hl, cy - hw]])


#: Default footprint per vehicle family (metres): small robots as discs,
#: cars as rectangles.
FAMILY_FOOTPRINTS = {
    "unicycle": ("disc", 0.2),
    "differential_drive": ("disc", 0.2),
    "integrator": ("disc", 0.2),
    "quadrotor": ("disc", 0.3),
    "blimp": ("disc", 1.0),
    "ackermann": ("rectangle", (4.5, 1.8)),
}


def default_footprint(family):
    """The default :class:`Footprint` of a vehicle family (see FAMILY_FOOTPRINTS)."""
    if family not in FAMILY_FOOTPRINTS:
        raise ParameterError("unknown vehicle family", param="family",
                             expected=sorted(FAMILY_FOOTPRINTS), found=family)
    kind, size = FAMILY_FOOTPRINTS[family]
    return Disc(size) if kind == "disc" else Rectangle(*size)
