"""avblocks.environment: obstacles, collisions, neighbours, communication,
range sensors and target detection.

- :class:`World` (plain data): obstacles (polygons, rectangles, circles,
  GeoJSON, WKT, occupancy bitmaps), bounds and walls, a :class:`Background`.
- :class:`Collision` and :class:`StopOnCollision` (footprints:
  :class:`Disc`, :func:`Rectangle`, :class:`PolygonFootprint`).
- :class:`Neighbors` (range, k-nearest, field of view) and the functions
  :func:`radius_neighbors`, :func:`knn`, :func:`fov_neighbors`,
  :func:`to_networkx`.
- :class:`CommChannel` (range, loss, latency), :class:`Gossip` and
  :class:`Broadcast` (information propagation).
- :class:`RangeSensor` (lidar-like rays) and :func:`cast_rays`.
- :class:`TargetDetection` (search and pickup).
- :class:`EdgeGrid` (``edges``): a world's obstacles as padded edge arrays
  with a uniform-grid broad phase, and the ``xp`` geometry kernels.

Every block here compiles (``backend="jax"``, ensembles, gradients):
agents find each other through the cell-list neighbour search of
:mod:`avblocks.utility.spatial` (O(N) per step at constant density, static
shapes planned by the compiled engine, overflows never silent), and
obstacles are padded edge arrays with a grid broad phase
(:class:`EdgeGrid`). In the NumPy engine each block uses what measured
fastest there: SciPy's k-d tree for neighbours, shapely's spatial index for
``Collision`` and ``RangeSensor`` (``method="auto"``; the grid method and
the exact shapely one are options), with the same results.
"""

from .collision import Collision, StopOnCollision, collide, collide_grid
from .comm import Broadcast, CommChannel, Gossip, gossip_step
from .edges import EdgeGrid
from .footprint import (
    FAMILY_FOOTPRINTS,
    Disc,
    Footprint,
    PolygonFootprint,
    Rectangle,
    default_footprint,
)
from .neighbors import (
    PAD_DISTANCE,
    Neighbors,
    fov_neighbors,
    knn,
    radius_neighbors,
    to_networkx,
)
from .range_sensor import RangeSensor, cast_rays, cast_rays_grid, ray_angles
from .targets import TargetDetection, detect_targets
from .world import Background, Circle, World, rectangle

__all__ = [
    "World", "Background", "Circle", "rectangle",
    "Footprint", "Disc", "PolygonFootprint", "Rectangle", "default_footprint",
    "FAMILY_FOOTPRINTS",
    "Collision", "StopOnCollision", "collide", "collide_grid", "EdgeGrid",
    "Neighbors", "radius_neighbors", "knn", "fov_neighbors", "to_networkx",
    "PAD_DISTANCE",
    "CommChannel", "Gossip", "Broadcast", "gossip_step",
    "RangeSensor", "cast_rays", "cast_rays_grid", "ray_angles",
    "TargetDetection", "detect_targets",
]
