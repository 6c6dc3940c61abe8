"""The world: static obstacles, bounds and a background picture.

A :class:`World` is plain data (not a block) that environment blocks take as
a parameter. Obstacles are indexed ``0 .. M-1`` in the order given; that
index is what :class:`~avblocks.environment.Collision` reports in
``hit_index``. Walls made from the bounds (``walls=True``) come last.

Obstacle kinds
--------------
- polygons: a vertex list ``[(x, y), ...]`` (any orientation, concave
  allowed) or a shapely ``Polygon`` (holes allowed) / ``MultiPolygon``
  (split into its parts);
- rectangles: :func:`rectangle` ``(xmin, ymin, xmax, ymax)``;
- circles: :class:`Circle` ``(center, radius)``, kept exact (collision and
  ray casting use the true circle; the polygon in ``world.geoms`` is only an
  inscribed approximation for drawing and the spatial index);
- loaded from GeoJSON or WKT (:meth:`World.from_geojson`,
  :meth:`World.from_wkt`) or from an occupancy bitmap
  (:meth:`World.from_occupancy`, :meth:`World.from_image`).

Example
-------
>>> from avblocks.environment import World, Circle, rectangle
>>> w = World([rectangle(0, 0, 1, 1), Circle((3, 0), 0.5)], bounds=(-5, -5, 5, 5))
>>> w.n_obstacles, w.segments.shape
(2, (4, 4))
>>> w.is_free([[0.5, 0.5], [2.0, 2.0]]).tolist()
[False, True]
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Point, Polygon
from shapely.geometry.base import BaseGeometry

from ..core.errors import ParameterError

#: Segments used to approximate a circle in ``World.geoms`` (per quarter).
CIRCLE_QUAD_SEGS = 16


@dataclass(frozen=True)
class Circle:
    """A circular obstacle (exact)."""

    center: tuple
    radius: float

    def __post_init__(self):
        c = np.asarray(self.center, dtype=float)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ParameterError("circle center must be (x, y)", param="center",
                                 expected="(2,) finite", found=c.shape)
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ParameterError("circle radius must be > 0", param="radius",
                                 expected="> 0", found=self.radius)
        object.__setattr__(self, "center", (float(c[0]), float(c[1])))
        object.__setattr__(self, "radius", float(self.radius))


def rectangle(xmin, ymin, xmax, ymax) -> Polygon:
    """An axis-aligned rectangle obstacle (a shapely polygon)."""
    if not (xmax > xmin and ymax > ymin):
        raise ParameterError("rectangle needs xmax > xmin and ymax > ymin",
                             param="rectangle", found=(xmin, ymin, xmax, ymax))
    return shapely.box(xmin, ymin, xmax, ymax)


@dataclass(frozen=True)
class Background:
    """A picture of the world for visualization: an image and its extent.

    ``image`` is an (H, W) or (H, W, 3|4) array whose row 0 is the top;
    ``extent`` is ``(xmin, xmax, ymin, ymax)`` in metres (Matplotlib's
    ``imshow(image, extent=extent)`` convention).
    """

    image: np.ndarray
    extent: tuple

    def __post_init__(self):
        img = np.asarray(self.image)
        if img.ndim not in (2, 3):
            raise ParameterError("background image must be (H, W) or (H, W, C)",
                                 param="image", found=img.shape)
        ext = tuple(float(v) for v in self.extent)
        if len(ext) != 4 or not (ext[1] > ext[0] and ext[3] > ext[2]):
            raise ParameterError("extent must be (xmin, xmax, ymin, ymax)",
                                 param="extent", found=self.extent)
        object.__setattr__(self, "image", img)
        object.__setattr__(self, "extent", ext)

    @classmethod
    def from_file(cls, path, extent):
        """Read an image file (anything Pillow reads)."""
        return cls(_read_image(path, gray=False), extent)


def _read_image(path, gray):
    from PIL import Image
    with Image.open(path) as im:
        im = im.convert("L" if gray else "RGB")
        return np.asarray(im)


def _as_polygons(item, where):
    """One user obstacle -> list of shapely polygons (or a Circle)."""
    if isinstance(item, Circle):
        return [item]
    if isinstance(item, BaseGeometry):
        if isinstance(item, Polygon):
            parts = [item]
        elif isinstance(item, MultiPolygon):
            parts = list(item.geoms)
        elif item.geom_type == "GeometryCollection":
            parts = [g for it in item.geoms if it.area > 0
                     for g in _as_polygons(it, where)]
        else:
            raise ParameterError("obstacle geometry must be a Polygon or "
                                 "MultiPolygon", param=where, found=item.geom_type)
    else:
        v = np.asarray(item, dtype=float)
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
            raise ParameterError("polygon obstacle must be a list of >= 3 (x, y) "
                                 "vertices", param=where, expected="(V >= 3, 2)",
                                 found=v.shape)
        if not np.all(np.isfinite(v)):       # GEOS fails on NaN/inf, deep inside
            raise ParameterError("polygon obstacle vertices must be finite numbers",
                                 param=where, found=v.tolist())
        parts = [Polygon(v)]
    out = []
    for p in parts:
        if isinstance(p, Circle):
            out.append(p)
            continue
        if p.is_empty or p.area <= 0:
            raise ParameterError("obstacle polygon has no area", param=where,
                                 found=p.wkt[:80])
        if not p.is_valid:
            fixed = shapely.get_parts(shapely.make_valid(p))
            out += [q for q in fixed if q.geom_type == "Polygon" and q.area > 0]
            continue
        out.append(p)
    return out


class World:
    """Static obstacles, optional bounds (and walls) and a background.

    Parameters
    ----------
    obstacles : sequence
        Vertex lists, shapely polygons, :func:`rectangle` s, :class:`Circle` s.
    bounds : (xmin, ymin, xmax, ymax), optional
        The world's extent (for sampling, plotting, walls).
    walls : bool
        Add four wall obstacles just outside ``bounds`` (so leaving the
        bounds is a collision and range sensors see the border). They get
        the last four obstacle indices.
    background : Background, optional
        A picture for visualization.

    Attributes
    ----------
    geoms : list of shapely Polygon
        One polygon per obstacle (circles approximated, for drawing).
    is_circle : (M,) bool
    circle_center : (M, 2) float (NaN for polygons)
    circle_radius : (M,) float (0 for polygons)
    segments : (S, 4) float
        Every polygon edge (exterior and holes) as ``x0, y0, x1, y1``.
    segment_owner : (S,) int64
        Obstacle index of each segment.
    tree : shapely.STRtree
        Spatial index over ``geoms`` (envelope queries).
    ray_tree : shapely.STRtree
        Index over the bounding boxes of ``segments`` then of the circles
        (``circle_ids``), for range sensors.
    """

    def __init__(self, obstacles=(), *, bounds=None, walls=False, background=None):
        items = []
        for k, ob in enumerate(obstacles):
            items += _as_polygons(ob, f"obstacles[{k}]")
        if bounds is not None:
            b = tuple(float(v) for v in bounds)
            if len(b) != 4 or not (b[2] > b[0] and b[3] > b[1]):
                raise ParameterError("bounds must be (xmin, ymin, xmax, ymax)",
                                     param="bounds", found=bounds)
            bounds = b
        elif walls:
            raise ParameterError("walls=True needs bounds", param="walls")
        self.n_user = len(items)
        if walls:
            x0, y0, x1, y1 = bounds
            t = max(x1 - x0, y1 - y0)
            items += [shapely.box(x0 - t, y0 - t, x0, y1 + t),
                      shapely.box(x1, y0 - t, x1 + t, y1 + t),
                      shapely.box(x0, y0 - t, x1, y0),
                      shapely.box(x0, y1, x1, y1 + t)]
        if background is not None and not isinstance(background, Background):
            raise ParameterError("background must be a Background", param="background",
                                 found=type(background).__name__)
        self.bounds = bounds
        self.walls = bool(walls)
        self.background = background
        m = len(items)
        self.is_circle = np.array([isinstance(it, Circle) for it in items], dtype=bool)
        self.circle_center = np.full((m, 2), np.nan)
        self.circle_radius = np.zeros(m)
        geoms = []
        for j, it in enumerate(items):
            if isinstance(it, Circle):
                self.circle_center[j] = it.center
                self.circle_radius[j] = it.radius
                geoms.append(Point(it.center).buffer(it.radius, quad_segs=CIRCLE_QUAD_SEGS))
            else:
                geoms.append(it)
        self.geoms = geoms
        self._geom_arr = np.array(geoms, dtype=object) if m else np.empty(0, object)
        self.tree = shapely.STRtree(self._geom_arr)
        segs, owner = [], []
        for j, g in enumerate(geoms):
            if self.is_circle[j]:
                continue
            for ring in (g.exterior, *g.interiors):
                c = np.asarray(ring.coords)
                segs.append(np.concatenate([c[:-1], c[1:]], axis=1))
                owner.append(np.full(len(c) - 1, j))
        self.segments = np.concatenate(segs) if segs else np.zeros((0, 4))
        self.segment_owner = (np.concatenate(owner).astype(np.int64) if owner
                              else np.zeros(0, np.int64))
        # index for ray casting: segment boxes, then circle boxes
        sg = self.segments
        self.circle_ids = np.nonzero(self.is_circle)[0]
        cc, cr = self.circle_center[self.circle_ids], self.circle_radius[self.circle_ids]
        lo = np.concatenate([np.minimum(sg[:, :2], sg[:, 2:]), cc - cr[:, None]])
        hi = np.concatenate([np.maximum(sg[:, :2], sg[:, 2:]), cc + cr[:, None]])
        self.ray_tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))

    # ------------------------------------------------------------ properties
    @property
    def n_obstacles(self) -> int:
        return len(self.geoms)

    def __repr__(self):
        return (f"World({self.n_obstacles} obstacles ({int(self.is_circle.sum())} "
                f"circles), bounds={self.bounds}, walls={self.walls})")

    # ------------------------------------------------------------- queries
    def is_free(self, points, clearance=0.0):
        """(N,) bool: points farther than ``clearance`` from every obstacle.

        Points on an obstacle's boundary (distance exactly ``clearance``)
        are not free. Points outside ``bounds`` are not free when the world
        has walls.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        r = np.full(len(p), float(clearance))
        ai, _ = _disc_obstacle_hits(self, p, r)
        free = np.ones(len(p), dtype=bool)
        free[ai] = False
        return free

    def sample_free(self, n, seed=0, clearance=0.0, max_rounds=100):
        """``n`` random free points (uniform in ``bounds``), shape (n, 2)."""
        if self.bounds is None:
            raise ParameterError("sample_free needs bounds", param="bounds")
        gen = np.random.default_rng(seed)
        x0, y0, x1, y1 = self.bounds
        out = np.zeros((0, 2))
        for _ in range(max_rounds):
            cand = gen.uniform([x0, y0], [x1, y1], size=(max(2 * n, 16), 2))
            out = np.concatenate([out, cand[self.is_free(cand, clearance)]])
            if len(out) >= n:
                return out[:n]
        raise ParameterError("could not find enough free points", param="n",
                             expected=n, found=len(out))

    # -------------------------------------------------------------- loaders
    @classmethod
    def from_wkt(cls, wkt, **kw):
        """Obstacles from WKT text (one string or a list; polygons and
        multipolygons; a GEOMETRYCOLLECTION is split)."""
        texts = [wkt] if isinstance(wkt, str) else list(wkt)
        geoms = [shapely.from_wkt(t) for t in texts]
        return cls(geoms, **kw)

    @classmethod
    def from_geojson(cls, src, **kw):
        """Obstacles from GeoJSON (a dict, a JSON string or a file path).

        Accepts a FeatureCollection, a Feature or a bare geometry. Polygons
        and MultiPolygons become polygon obstacles; a Point feature with a
        ``radius`` property becomes a :class:`Circle`. Coordinates are taken
        as metres in the world frame (no map projection).
        """
        if isinstance(src, dict):
            data = src
        else:
            s = str(src)
            if s.lstrip().startswith("{"):
                data = json.loads(s)
            else:
                with open(s) as fh:
                    data = json.load(fh)
        feats = (data["features"] if data.get("type") == "FeatureCollection"
                 else [data])
        obs = []
        for f in feats:
            geom = f["geometry"] if f.get("type") == "Feature" else f
            props = (f.get("properties") or {}) if f.get("type") == "Feature" else {}
            g = shapely.from_geojson(json.dumps(geom))
            if g.geom_type == "Point":
                if "radius" not in props:
                    raise ParameterError("a GeoJSON Point obstacle needs a 'radius' "
                                         "property", param="geojson")
                obs.append(Circle((g.x, g.y), float(props["radius"])))
            else:
                obs.append(g)
        return cls(obs, **kw)

    @classmethod
    def from_occupancy(cls, grid, resolution, origin=(0.0, 0.0), *, threshold=0.5,
                       image_rows=True, **kw):
        """Obstacles from an occupancy grid: occupied cells merged into polygons.

        Parameters
        ----------
        grid : (H, W) array
            Cell values; a cell is occupied when its value is ``> threshold``
            (booleans: True is occupied).
        resolution : float
            Cell size in metres.
        origin : (x, y)
            World coordinates of the lower-left corner of the grid.
        image_rows : bool
            True (default, image / ROS map_server convention): row 0 is the
            top row of the map. False: row 0 is the bottom row (y = origin y).

        Notes
        -----

        ``bounds`` defaults to the grid's extent.
        """
        g = np.asarray(grid)
        if g.ndim != 2:
            raise ParameterError("occupancy grid must be 2-D", param="grid", found=g.shape)
        res = float(resolution)
        if not (np.isfinite(res) and res > 0):
            raise ParameterError("resolution must be > 0", param="resolution", found=res)
        occ = g.astype(bool) if g.dtype == bool else g.astype(float) > threshold
        h, w = occ.shape
        ox, oy = float(origin[0]), float(origin[1])
        rows_y = (h - 1 - np.arange(h)) if image_rows else np.arange(h)
        # run-length encode each row: one rectangle per run of occupied cells
        pad = np.zeros((h, 1), dtype=bool)
        d = np.diff(np.concatenate([pad, occ, pad], axis=1).astype(np.int8), axis=1)
        r_s, c_s = np.nonzero(d == 1)
        r_e, c_e = np.nonzero(d == -1)
        y = rows_y[r_s]
        boxes = shapely.box(ox + c_s * res, oy + y * res, ox + c_e * res, oy + (y + 1) * res)
        polys = []
        if len(boxes):
            merged = shapely.union_all(boxes)
            merged = shapely.simplify(merged, 0.0)
            polys = [p for p in shapely.get_parts(merged) if p.area > 0]
        kw.setdefault("bounds", (ox, oy, ox + w * res, oy + h * res))
        return cls(polys, **kw)

    @classmethod
    def from_image(cls, path, resolution, origin=(0.0, 0.0), *, occupied_thresh=0.65,
                   negate=False, background=True, **kw):
        """Obstacles from a map image (ROS map_server convention).

        A pixel's occupancy is ``(255 - gray) / 255`` (dark is occupied;
        ``negate=True`` flips it) and it is an obstacle when that exceeds
        ``occupied_thresh``. Row 0 of the image is the top of the map and
        ``origin`` is the lower-left corner. With ``background=True`` the
        image becomes the world's background with the matching extent.
        """
        gray = _read_image(path, gray=True).astype(float)
        occ = gray / 255.0 if negate else (255.0 - gray) / 255.0
        if background and "background" not in kw:
            h, w = gray.shape
            ox, oy = float(origin[0]), float(origin[1])
            kw["background"] = Background.from_file(
                path, (ox, ox + w * resolution, oy, oy + h * resolution))
        return cls.from_occupancy(occ, resolution, origin, threshold=occupied_thresh,
                                  image_rows=True, **kw)


def _disc_obstacle_hits(world, centers, radii):
    """(agent, obstacle) index pairs where discs touch obstacles (exact)."""
    if world.n_obstacles == 0 or len(centers) == 0:
        e = np.zeros(0, np.int64)
        return e, e
    cx, cy = centers[:, 0], centers[:, 1]
    boxes = shapely.box(cx - radii, cy - radii, cx + radii, cy + radii)
    a, o = world.tree.query(boxes)
    circ = world.is_circle[o]
    hit = np.zeros(len(a), dtype=bool)
    if np.any(~circ):
        ap, op = a[~circ], o[~circ]
        pts = shapely.points(centers[ap])
        hit[~circ] = shapely.distance(pts, world._geom_arr[op]) <= radii[ap]
    if np.any(circ):
        ac, oc = a[circ], o[circ]
        d = np.hypot(*(centers[ac] - world.circle_center[oc]).T)
        hit[circ] = d <= radii[ac] + world.circle_radius[oc]
    return a[hit].astype(np.int64), o[hit].astype(np.int64)
