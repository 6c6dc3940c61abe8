"""Obstacle edge arrays and their xp kernels against shapely (independent
truth): random star-shaped (concave) polygons, a polygon with a hole,
exact circles, walls; points on vertices and edges; JAX equal to NumPy."""

import numpy as np
import pytest
import shapely

from avblocks.environment import Circle, World, rectangle
from avblocks.environment.edges import (
    EdgeGrid,
    point_in_polygons,
    point_segment_distance,
    ray_circle,
    ray_segment,
    world_edges,
)


def star(rng, c, r0, r1, k):
    a = np.sort(rng.uniform(0, 2 * np.pi, k))
    r = rng.uniform(r0, r1, k)
    return np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a)]


def random_world(seed, walls=True):
    rng = np.random.default_rng(seed)
    obs = [star(rng, rng.uniform(-8, 8, 2), 0.5, 3.0, int(rng.integers(5, 12)))
           for _ in range(8)]
    obs += [Circle((3, 3), 1.0), rectangle(-2, -2, 0, 0),
            shapely.Polygon([(5, -9), (9, -9), (9, -5), (5, -5)],
                            [[(6, -8), (8, -8), (8, -6), (6, -6)]])]
    return World(obs, bounds=(-10, -10, 10, 10), walls=walls)


def shapely_disc_hits(world, p, r):
    """Per point, lowest obstacle index with distance <= r (true circles)."""
    n, m = len(p), world.n_obstacles
    pts = shapely.points(p)
    first = np.full(n, -1)
    for j in range(m - 1, -1, -1):
        if world.is_circle[j]:
            d = np.hypot(*(p - world.circle_center[j]).T) - world.circle_radius[j]
            d = np.maximum(d, 0)
        else:
            d = shapely.distance(pts, world.geoms[j])
        first = np.where(d <= r, j, first)
    return first


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_disc_hits_match_shapely(seed):
    w = random_world(seed)
    g = EdgeGrid(w, 0.6)
    rng = np.random.default_rng(seed + 10)
    p = rng.uniform(-11, 11, (4000, 2))
    r = rng.uniform(0, 0.6, len(p))
    hit, first = g.disc_hits(p, r)
    want = shapely_disc_hits(w, p, r)
    np.testing.assert_array_equal(first, want)
    np.testing.assert_array_equal(hit, want >= 0)
    assert 0 < hit.mean() < 1


def test_points_on_vertices_and_edges_touch():
    w = random_world(3, walls=False)
    g = EdgeGrid(w, 0.3)
    s = w.segments
    for q in (s[:, :2], s[:, 2:]):                        # vertices exactly
        hit, first = g.disc_hits(q, 0.0)
        assert hit.all()
        np.testing.assert_array_equal(first, shapely_disc_hits(w, q, 0.0))
    # points a hair inside/outside of edge midpoints: parity decides
    mid = 0.5 * (s[:, :2] + s[:, 2:])
    nrm = np.c_[s[:, 3] - s[:, 1], s[:, 0] - s[:, 2]]
    nrm /= np.hypot(*nrm.T)[:, None]
    for sgn in (1, -1):
        q = mid + sgn * 1e-7 * nrm
        hit, first = g.disc_hits(q, 0.0)
        np.testing.assert_array_equal(first, shapely_disc_hits(w, q, 0.0))


def test_inside_on_cell_grid_points():
    """Query points on cell borders and exactly at reference-point rows."""
    w = random_world(4)
    g = EdgeGrid(w, 0.5)
    xs = g.origin[0] + g.cell * np.arange(g.shape[0] + 1)
    ys = g.origin[1] + g.cell * np.arange(g.shape[1] + 1)
    q = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    q = np.concatenate([q, g.cell_ref])
    _, first = g.disc_hits(q, 0.0)
    np.testing.assert_array_equal(first, shapely_disc_hits(w, q, 0.0))


def test_brute_point_in_polygon_matches_shapely():
    w = random_world(5, walls=False)
    seg, owner = world_edges(w)
    rng = np.random.default_rng(1)
    p = rng.uniform(-11, 11, (3000, 2))
    got = point_in_polygons(p, seg, owner, w.n_obstacles)
    for j in np.nonzero(~w.is_circle)[0]:
        np.testing.assert_array_equal(got[:, j], shapely.contains_xy(w.geoms[j], *p.T))


def test_point_segment_distance_matches_shapely():
    rng = np.random.default_rng(2)
    a, b, p = rng.normal(size=(3, 500, 2))
    b[:10] = a[:10]                                       # degenerate segments
    d = point_segment_distance(p[:, 0], p[:, 1], a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    want = shapely.distance(shapely.points(p), shapely.linestrings(np.stack([a, b], 1)))
    np.testing.assert_allclose(d, want, rtol=0, atol=1e-12)


def test_ray_kernels_match_shapely():
    rng = np.random.default_rng(3)
    o = rng.uniform(-1, 1, (400, 2))
    th = rng.uniform(-np.pi, np.pi, 400)
    u = np.c_[np.cos(th), np.sin(th)]
    a, b = rng.uniform(-3, 3, (2, 400, 2))
    t = ray_segment(o[:, 0], o[:, 1], u[:, 0], u[:, 1], a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    far = o + 100 * u
    inter = shapely.intersection(shapely.linestrings(np.stack([o, far], 1)),
                                 shapely.linestrings(np.stack([a, b], 1)))
    want = np.where(shapely.is_empty(inter), np.inf,
                    shapely.distance(shapely.points(o), inter))
    np.testing.assert_allclose(t, want, rtol=1e-9, atol=1e-9)
    c = rng.uniform(-3, 3, (400, 2))
    r = rng.uniform(0.1, 2, 400)
    t = ray_circle(o[:, 0], o[:, 1], u[:, 0], u[:, 1], c[:, 0], c[:, 1], r)
    disc = shapely.buffer(shapely.points(c), r, quad_segs=256)
    inter = shapely.intersection(shapely.linestrings(np.stack([o, far], 1)), disc)
    want = np.where(shapely.is_empty(inter), np.inf,
                    shapely.distance(shapely.points(o), inter))
    fin = np.isfinite(want) & np.isfinite(t)
    assert np.array_equal(np.isfinite(t), np.isfinite(want)) or \
        np.mean(np.isfinite(t) != np.isfinite(want)) < 0.01      # grazing rays only
    np.testing.assert_allclose(t[fin], want[fin], atol=2e-4)    # polygonal circle


@pytest.mark.jax
def test_disc_hits_traced_equal_numpy():
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp
    w = random_world(6)
    g = EdgeGrid(w, 0.6)
    rng = np.random.default_rng(7)
    p = rng.uniform(-11, 11, (2000, 2))
    r = rng.uniform(0, 0.6, len(p))
    want = g.disc_hits(p, r)
    from avblocks.core.compiled._jax import x64
    with x64(True):
        got = jax.jit(lambda p, r: g.disc_hits(p, r, jnp))(p, r)
    np.testing.assert_array_equal(np.asarray(got[0]), want[0])
    np.testing.assert_array_equal(np.asarray(got[1]), want[1])


def test_occupancy_world_edges_on_cell_centres():
    """An occupancy map whose edges lie on the grid's cell-centre lines
    (reference points nudged off them): grid answers equal shapely's."""
    occ = np.random.default_rng(8).random((40, 40)) > 0.8
    w = World.from_occupancy(occ, 0.5)
    g = EdgeGrid(w, 0.25, cell=0.5)          # centres at multiples of 0.25 + origin
    assert np.all(np.abs(g.cell_ref - (g.origin + 0.5 * g.cell
                                       + g.cell * np.floor((g.cell_ref - g.origin)
                                                           / g.cell))) < 0.2 * g.cell)
    rng = np.random.default_rng(9)
    q = np.concatenate([rng.uniform(-1, 21, (3000, 2)),
                        np.round(rng.uniform(-1, 21, (1000, 2)) * 4) / 4])   # on lines
    r = rng.uniform(0, 0.25, len(q))
    _, first = g.disc_hits(q, r)
    np.testing.assert_array_equal(first, shapely_disc_hits(w, q, r))


def test_segment_segment_distance_matches_shapely():
    from avblocks.environment.edges import segment_segment_dist2, segment_segment_distance
    rng = np.random.default_rng(4)
    a0, a1, b0, b1 = rng.uniform(-1, 1, (4, 2000, 2))
    b0[:50], b1[:50] = a0[:50] + 0.5 * (a1[:50] - a0[:50]), a1[:50] + (a1[:50] - a0[:50])
    b0[50:100] = a1[50:100]                                # shared endpoint
    args = (a0[:, 0], a0[:, 1], a1[:, 0], a1[:, 1], b0[:, 0], b0[:, 1], b1[:, 0], b1[:, 1])
    d = segment_segment_distance(*args)
    want = shapely.distance(shapely.linestrings(np.stack([a0, a1], 1)),
                            shapely.linestrings(np.stack([b0, b1], 1)))
    np.testing.assert_allclose(d, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(segment_segment_dist2(*args), want ** 2, rtol=0, atol=1e-12)
    assert np.all(d[50:100] == 0)
