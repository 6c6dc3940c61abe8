"""Geometry for the live view: agent shapes, obstacle meshes, colours,
camera framing. Plain NumPy/shapely; nothing here talks to the browser."""

from __future__ import annotations

import numpy as np

#: Flat arrow (ground agents), nose along +x, in metres before scaling.
ARROW_2D = (np.array([[0.5, 0.0, 0.0], [-0.35, 0.3, 0.0], [-0.2, 0.0, 0.0],
                      [-0.35, -0.3, 0.0]]),
            np.array([[0, 1, 2], [0, 2, 3]]))
#: A small dart (UAVs): a tetrahedron-like body, nose along +x, fin up.
DART_3D = (np.array([[0.5, 0.0, 0.0], [-0.35, 0.3, 0.0], [-0.35, -0.3, 0.0],
                     [-0.3, 0.0, 0.2]]),
           np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]))

_TAB10 = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40],
                   [148, 103, 189], [140, 86, 75], [227, 119, 194], [127, 127, 127],
                   [188, 189, 34], [23, 190, 207]], dtype=np.uint8)


def agent_colors(n, colors=None):
    """(n, 3) uint8 colours: ``colors`` may be None (tab10 cycle), one colour
    (name, hex or RGB in 0..1 or 0..255) or one per agent."""
    from matplotlib.colors import to_rgb

    from ...core.errors import ParameterError
    if colors is None:
        return _TAB10[np.arange(n) % len(_TAB10)]
    if isinstance(colors, str):
        return np.tile((np.array(to_rgb(colors)) * 255).round().astype(np.uint8), (n, 1))
    if isinstance(colors, (list, tuple)) and colors and isinstance(colors[0], str):
        rgb = np.array([to_rgb(c) for c in colors])
    else:
        rgb = np.asarray(colors, dtype=float)
        if rgb.size and rgb.max() > 1.0:
            rgb = rgb / 255.0
    if rgb.shape == (3,):
        rgb = np.tile(rgb, (n, 1))
    if rgb.shape != (n, 3) or not np.all((rgb >= 0) & (rgb <= 1)):
        raise ParameterError("colors must be one colour or one per agent",
                             param="colors", expected=f"(3,) or ({n}, 3)",
                             found=getattr(rgb, "shape", None))
    return (rgb * 255).round().astype(np.uint8)


def yaw_quaternions(theta):
    """(N, 4) w, x, y, z of rotations by ``theta`` about +z."""
    h = 0.5 * np.asarray(theta, dtype=float)
    q = np.zeros((h.shape[0], 4))
    q[:, 0] = np.cos(h)
    q[:, 3] = np.sin(h)
    return q


def prism(polygon, height, z0=0.0):
    """(vertices, faces) of a shapely polygon extruded from ``z0`` to
    ``z0 + height`` (top cap triangulated, holes kept; walls as quads)."""
    import shapely
    tris = shapely.constrained_delaunay_triangles(polygon)
    verts, faces = [], []
    for t in tris.geoms:
        c = np.asarray(t.exterior.coords)[:3]
        base = len(verts)
        verts += [(x, y, z0 + height) for x, y in c]
        faces.append((base, base + 1, base + 2))
    for ring in (polygon.exterior, *polygon.interiors):
        c = np.asarray(ring.coords)
        for (x0, y0), (x1, y1) in zip(c[:-1, :2], c[1:, :2]):
            base = len(verts)
            verts += [(x0, y0, z0), (x1, y1, z0), (x1, y1, z0 + height),
                      (x0, y0, z0 + height)]
            faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(verts, dtype=float), np.array(faces, dtype=np.uint32)


def outline_segments(polygon, z=0.0):
    """(S, 2, 3) segments of a polygon's rings at height ``z``."""
    segs = []
    for ring in (polygon.exterior, *polygon.interiors):
        c = np.asarray(ring.coords)[:, :2]
        s = np.zeros((len(c) - 1, 2, 3))
        s[:, 0, :2], s[:, 1, :2], s[:, :, 2] = c[:-1], c[1:], z
        segs.append(s)
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3))


def frame_extent(points, worlds):
    """(xmin, xmax, ymin, ymax) covering the points and the worlds' bounds
    and obstacles, with a margin."""
    xs, ys = [], []
    p = np.asarray(points, dtype=float).reshape(-1, points.shape[-1]) if len(points) else \
        np.zeros((0, 2))
    if len(p):
        xs += [p[:, 0].min(), p[:, 0].max()]
        ys += [p[:, 1].min(), p[:, 1].max()]
    for w in worlds:
        if w.bounds is not None:
            xs += [w.bounds[0], w.bounds[2]]
            ys += [w.bounds[1], w.bounds[3]]
        for g in w.geoms[: w.n_user]:
            b = g.bounds
            xs += [b[0], b[2]]
            ys += [b[1], b[3]]
    if not xs:
        return (-5.0, 5.0, -5.0, 5.0)
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    m = max(1.0, 0.08 * max(x1 - x0, y1 - y0))
    return (x0 - m, x1 + m, y0 - m, y1 + m)


def grid_segments(extent, z=-0.01):
    """(S, 2, 3) lines of a grid over ``extent`` at a round spacing
    (10 to 25 lines across the larger side)."""
    x0, x1, y0, y1 = extent
    span = max(x1 - x0, y1 - y0)
    step = 10.0 ** np.floor(np.log10(span / 10))
    for m in (1, 2, 5, 10):
        if span / (m * step) <= 25:
            step *= m
            break
    xs = np.arange(np.ceil(x0 / step), np.floor(x1 / step) + 1) * step
    ys = np.arange(np.ceil(y0 / step), np.floor(y1 / step) + 1) * step
    seg = [[[x, y0, z], [x, y1, z]] for x in xs] + [[[x0, y, z], [x1, y, z]] for y in ys]
    return np.array(seg, dtype=float).reshape(-1, 2, 3)
