"""The closed-form box kernels and the dense queries of small worlds against
shapely (independent truth) and against the grid path: rectangles and walls
as boxes, a concave polygon, a polygon with a hole and a circle left to the
edge kernels; points inside obstacles, on edges and outside the walls."""

import numpy as np
import pytest
import shapely

from avblocks.environment import Circle, Collision, Disc, RangeSensor, World, rectangle
from avblocks.environment.boxes import (
    DENSE_ITEMS,
    boundary_distance,
    box_boundary_distance,
    box_dist2,
    split_boxes,
)
from avblocks.environment.edges import EdgeGrid, world_edges


def small_world():
    """2 rectangles + 4 walls (boxes), a concave L, a square with a hole, a
    circle: 21 items, queried densely."""
    ell = [(4, 4), (7, 4), (7, 5), (5, 5), (5, 7), (4, 7)]
    holed = shapely.Polygon([(-8, 3), (-3, 3), (-3, 8), (-8, 8)],
                            [[(-7, 4), (-4, 4), (-4, 7), (-7, 7)]])
    return World([rectangle(-2, -2, 1, -1), rectangle(2, -7, 3, -3), ell, holed,
                  Circle((-5, -5), 1.5)], bounds=(-9, -9, 9, 9), walls=True)


def test_split_boxes_finds_the_rectangles_and_walls():
    w = small_world()
    seg, owner = world_edges(w)
    boxes, own, rest = split_boxes(seg, owner)
    assert own.tolist() == [0, 1, 5, 6, 7, 8]                   # 2 rectangles, 4 walls
    np.testing.assert_array_equal(boxes[0], [-2, -2, 1, -1])
    assert sorted(set(owner[rest].tolist())) == [2, 3]          # the L and the holed square
    g = EdgeGrid(w, 1.0)
    assert g.dense and len(g.boxes) + len(g.rest) + g.n_circles <= DENSE_ITEMS
    # a rotated square is not a box
    tilted = World([[(0, -1), (1, 0), (0, 1), (-1, 0)]])
    assert len(EdgeGrid(tilted, 1.0).boxes) == 0


def test_box_distances_match_shapely():
    rng = np.random.default_rng(0)
    b = np.array([[-1.0, -0.5, 2.0, 1.5], [3.0, 3.0, 3.5, 6.0]])
    p = rng.uniform(-2, 7, (3000, 2))
    p[:4] = [[-1.0, 0.0], [2.0, 1.5], [0.5, 0.5], [3.25, 4.5]]   # on an edge, a corner, inside
    px, py = p[:, 0:1], p[:, 1:2]
    polys = [shapely.box(*bb) for bb in b]
    pts = shapely.points(p)
    want_in = np.stack([shapely.distance(pts, q) for q in polys], 1)
    want_bd = np.stack([shapely.distance(pts, q.boundary) for q in polys], 1)
    d2 = box_dist2(px, py, b[:, 0], b[:, 1], b[:, 2], b[:, 3])
    np.testing.assert_allclose(np.sqrt(d2), want_in, atol=1e-12)
    bd = box_boundary_distance(px, py, b[:, 0], b[:, 1], b[:, 2], b[:, 3])
    np.testing.assert_allclose(bd, want_bd, atol=1e-12)
    assert (want_in == 0).any() and (want_in > 0).any()


def test_boundary_distance_of_a_world_matches_shapely():
    w = small_world()
    seg, owner = world_edges(w)
    boxes, _, rest = split_boxes(seg, owner)
    rng = np.random.default_rng(1)
    p = rng.uniform(-10, 10, (2000, 2))
    got = boundary_distance(p[:, 0:1], p[:, 1:2], boxes, seg.reshape(-1, 4)[rest])
    lines = shapely.union_all([g.boundary for j, g in enumerate(w.geoms) if not w.is_circle[j]])
    want = shapely.distance(shapely.points(p), lines)
    np.testing.assert_allclose(got, want, atol=1e-12)


def _shapely_first(world, p, r):
    first = np.full(len(p), -1)
    pts = shapely.points(p)
    for j in range(world.n_obstacles - 1, -1, -1):
        if world.is_circle[j]:
            d = np.maximum(np.hypot(*(p - world.circle_center[j]).T)
                           - world.circle_radius[j], 0)
        else:
            d = shapely.distance(pts, world.geoms[j])
        first = np.where(d <= r, j, first)
    return first


def test_dense_disc_hits_match_shapely_and_the_grid():
    w = small_world()
    g = EdgeGrid(w, 0.6)
    assert g.dense
    rng = np.random.default_rng(2)
    p = rng.uniform(-10, 10, (4000, 2))
    p[:3] = [[-5.5, 5.5], [-7.0, 5.0], [6.0, 4.5]]      # in the hole, on its edge, in the L
    r = rng.uniform(0, 0.6, len(p))
    hit, first = g.disc_hits(p, r)
    want = _shapely_first(w, p, r)
    np.testing.assert_array_equal(first, want)
    np.testing.assert_array_equal(hit, want >= 0)
    g.dense = False                                      # the cell-list path agrees
    hit2, first2 = g.disc_hits(p, r)
    np.testing.assert_array_equal(first2, want)
    assert 0.1 < hit.mean() < 0.9


@pytest.mark.parametrize("agents", [None, 0.4])
def test_dense_ray_casts_match_shapely(agents):
    w = small_world()
    rng = np.random.default_rng(3)
    n = 60
    pose = np.c_[rng.uniform(-10, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    pose[:3, :2] = [[-5.5, 5.5], [-1.0, -1.5], [9.5, 0.0]]   # hole, in a box, in a wall
    kw = dict(n_rays=24, max_range=6.0, agent_radius=agents)
    s = RangeSensor(w, n, method="grid", **kw)
    assert s.edges.dense
    a = s.output(0.0, {}, {"pose": pose}, np)["ranges"]
    b = RangeSensor(w, n, method="shapely", **kw).output(0.0, {}, {"pose": pose}, np)
    np.testing.assert_allclose(a, b["ranges"], rtol=0, atol=1e-9)
    assert 0.2 < np.mean(a < 6.0) < 0.95
    # world-frame rays (position input): the same fan for every agent
    p = RangeSensor(w, n, input="position", method="grid", **kw)
    q = RangeSensor(w, n, input="position", method="shapely", **kw)
    np.testing.assert_allclose(p.output(0.0, {}, {"position": pose[:, :2]}, np)["ranges"],
                               q.output(0.0, {}, {"position": pose[:, :2]}, np)["ranges"],
                               rtol=0, atol=1e-9)


@pytest.mark.jax
def test_dense_queries_traced_equal_numpy():
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from avblocks.core.compiled._jax import x64
    w = small_world()
    rng = np.random.default_rng(4)
    n = 8
    pose = np.c_[rng.uniform(-9, 9, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    s = RangeSensor(w, n, n_rays=16, max_range=5.0, agent_radius=0.3, method="grid")
    c = Collision(w, n, footprint=Disc(0.5), method="grid")
    want_r = s.output(0.0, {}, {"pose": pose}, np)["ranges"]
    want_c = c.output(0.0, {}, {"pose": pose}, np)
    with x64(True):
        got_r = jax.jit(lambda p: s.output(0.0, {}, {"pose": p}, jnp)["ranges"])(pose)
        got_c = jax.jit(lambda p: c.output(0.0, {}, {"pose": p}, jnp))(pose)
    np.testing.assert_allclose(np.asarray(got_r), want_r, rtol=0, atol=1e-12)
    for k in ("collision", "hit_index", "hit_agent_index"):
        np.testing.assert_array_equal(np.asarray(got_c[k]), want_c[k])
