"""Collision: hand-built known answers, brute-force cross-check, simulation."""

import numpy as np
import pytest
import shapely

import avblocks as av
from avblocks.environment import (
    Circle,
    Collision,
    Disc,
    PolygonFootprint,
    Rectangle,
    StopOnCollision,
    World,
    collide,
    rectangle,
)

SQUARE = rectangle(1.0, -1.0, 2.0, 1.0)


def col(world, pose, fp, **kw):
    return collide(world, np.atleast_2d(np.asarray(pose, float)), fp, **kw)


@pytest.mark.parametrize("fp", [Disc(0.5), Rectangle(1.0, 1.0)])
def test_touching_overlapping_separated(fp):
    w = World([SQUARE])
    # footprint's right edge at x = 1.0 exactly: touching counts
    assert col(w, [0.5, 0.0, 0.0], fp)["hit_obstacle"].tolist() == [True]
    assert col(w, [0.8, 0.3, 0.0], fp)["hit_obstacle"].tolist() == [True]
    r = col(w, [0.499, 0.0, 0.0], fp)  # separated by 1 mm
    assert r["hit_obstacle"].tolist() == [False]
    assert r["hit_index"].tolist() == [-1]
    assert r["collision"].tolist() == [False]


def test_rotated_footprints():
    w = World([rectangle(0.5, 0.5, 1.5, 1.5)])
    stick = Rectangle(2.0, 0.2)  # from x=-1 to 1 in the body frame
    poses = np.array([[0, 0, 0.0], [0, 0, np.pi / 4], [0, 0, np.pi / 2],
                      [0, 0, -3 * np.pi / 4]])
    # at pi/4 and -3pi/4 the stick's tip (0.707, 0.707) lies inside the square
    assert col(w, poses, stick)["hit_obstacle"].tolist() == [False, True, False, True]
    # two sticks crossing only when rotated
    pair = np.array([[0, 0, 0.0], [0, 0.9, 0.0]])
    assert not col(World(), pair, stick)["hit_agent"].any()
    pair[1, 2] = np.pi / 2
    r = col(World(), pair, stick)
    assert r["hit_agent"].tolist() == [True, True]
    assert r["hit_agent_index"].tolist() == [1, 0]


def test_concave_obstacle():
    # U shape: notch x in [1, 2], y in [1, 3]
    u = [(0, 0), (3, 0), (3, 3), (2, 3), (2, 1), (1, 1), (1, 3), (0, 3)]
    w = World([u])
    assert col(w, [1.5, 2.0], Disc(0.3))["hit_obstacle"].tolist() == [False]
    assert col(w, [1.5, 2.0], Disc(0.5))["hit_obstacle"].tolist() == [True]  # touches
    long = Rectangle(1.2, 0.5)
    assert col(w, [1.5, 2.0, 0.0], long)["hit_obstacle"].tolist() == [True]
    assert col(w, [1.5, 2.0, np.pi / 2], long)["hit_obstacle"].tolist() == [False]


def test_agent_inside_hole():
    donut = shapely.Polygon([(-5, -5), (5, -5), (5, 5), (-5, 5)],
                            holes=[[(-2, -2), (2, -2), (2, 2), (-2, 2)]])
    w = World([donut])
    r = col(w, [[0, 0], [1.5, 0], [1.49, 0], [3.5, 0], [0, -1.5]], Disc(0.5))
    assert r["hit_obstacle"].tolist() == [False, True, False, True, True]
    sq = Rectangle(1.0, 1.0)
    r = col(w, [[0, 0, 0], [1.4, 0, 0], [1.2, 0, np.pi / 4]], sq)
    # rotated square: half diagonal 0.7071 -> reaches x = 1.907 < 2
    assert r["hit_obstacle"].tolist() == [False, False, False]
    r = col(w, [[1.5, 0, 0], [1.3, 0, np.pi / 4]], sq)
    assert r["hit_obstacle"].tolist() == [True, True]


def test_circle_obstacle_is_exact_and_hit_index():
    w = World([rectangle(10, 10, 11, 11), Circle((0, 0), 1.0), rectangle(-0.2, -0.2, 0.2, 0.2)])
    # touching the true circle between two vertices of its drawing polygon
    # (there the polygon lies ~0.5 mm inside the circle)
    a = np.deg2rad(5.0)
    p = 1.5 * np.array([np.cos(a), np.sin(a)])
    assert col(w, p * (1 - 1e-9), Disc(0.5))["hit_obstacle"].tolist() == [True]
    assert col(w, p * 1.0001, Disc(0.5))["hit_obstacle"].tolist() == [False]
    r = col(w, [[1.5, 0, 0], [2.001, 0, 0]], Rectangle(1.0, 1.0))
    assert r["hit_obstacle"].tolist() == [True, False]
    # overlapping obstacles 1 and 2: the lowest index is reported
    r = col(w, [[0, 0, 0], [10.5, 10.5, 0], [5, 5, 0]], Disc(0.1))
    assert r["hit_index"].tolist() == [1, 0, -1]


def test_walls_and_agents():
    w = World([], bounds=(0, 0, 10, 10), walls=True)
    assert w.n_obstacles == 4 and w.n_user == 0
    r = col(w, [[0.4, 5], [5, 5], [5, 9.6], [5.0, 6.0]], Disc(0.5))
    assert r["hit_obstacle"].tolist() == [True, False, True, False]
    assert r["hit_index"].tolist() == [0, -1, 3, -1]
    # agents 1 and 3 touch each other (distance 1 = 0.5 + 0.5)
    assert r["hit_agent"].tolist() == [False, True, False, True]
    assert r["hit_agent_index"].tolist() == [-1, 3, -1, 1]
    r = col(w, [[5, 5], [5, 6.001]], Disc(0.5))
    assert not r["hit_agent"].any()
    # per-agent radii
    r = col(World(), [[0, 0], [1.0, 0], [2.6, 0]], Disc([0.3, 0.7, 0.2]))
    assert r["hit_agent"].tolist() == [True, True, False]


def test_margin():
    w = World([SQUARE])
    assert not col(w, [0.4, 0, 0], Disc(0.5))["collision"][0]
    assert col(w, [0.4, 0, 0], Disc(0.5), margin=0.1)["collision"][0]
    assert col(w, [0.4, 0, 0], Rectangle(1.0, 1.0), margin=0.1)["collision"][0]
    assert not col(w, [0.38, 0, 0], Rectangle(1.0, 1.0), margin=0.1)["collision"][0]


def _random_world(gen, m=50, size=50.0):
    obs = []
    for k in range(m):
        c = gen.uniform(0, size, 2)
        if k % 5 == 0:
            obs.append(Circle(c, gen.uniform(0.5, 2.0)))
        else:
            pts = c + gen.normal(0, 1.5, (8, 2))
            hull = shapely.MultiPoint(pts).convex_hull
            if k % 5 == 1:  # a concave one: hull minus a bite
                hull = hull.difference(shapely.Point(c).buffer(0.8))
                hull = max(shapely.get_parts(hull), key=lambda g: g.area)
            obs.append(hull)
    return World(obs)


def _brute(world, pose, fp):
    n = len(pose)
    obs = np.array(world.geoms, dtype=object)
    if isinstance(fp, Disc):
        pts = shapely.points(pose[:, :2])
        r = fp.radii(n)
        d = shapely.distance(pts[:, None], obs[None, :])
        cd = np.hypot(pose[:, None, 0] - world.circle_center[None, :, 0],
                      pose[:, None, 1] - world.circle_center[None, :, 1])
        d = np.where(world.is_circle[None, :], cd - world.circle_radius[None, :], d)
        M = d <= r[:, None]
        dd = np.hypot(*(pose[:, None, :2] - pose[None, :, :2]).transpose(2, 0, 1))
        A = dd <= r[:, None] + r[None, :]
    else:
        polys = fp.posed(pose)
        M = shapely.intersects(polys[:, None], obs[None, :])
        cd = shapely.distance(polys[:, None], shapely.points(
            np.nan_to_num(world.circle_center))[None, :])
        M = np.where(world.is_circle[None, :], cd <= world.circle_radius[None, :], M)
        A = shapely.intersects(polys[:, None], polys[None, :])
    np.fill_diagonal(A, False)
    first = np.where(M.any(1), M.argmax(1), -1)
    return M.any(1), A.any(1), first


@pytest.mark.parametrize("fp", [Disc(0.8), Rectangle(1.6, 0.8),
                                PolygonFootprint([(1, 0), (-0.6, 0.6), (-0.2, 0), (-0.6, -0.6)])])
def test_random_against_brute_force(fp):
    gen = np.random.default_rng(7)
    w = _random_world(gen)
    pose = np.c_[gen.uniform(0, 50, (300, 2)), gen.uniform(-np.pi, np.pi, 300)]
    r = collide(w, pose, fp)
    ho, ha, first = _brute(w, pose, fp)
    assert 20 < ho.sum() < 280 and ha.sum() > 5  # the case is not trivial
    np.testing.assert_array_equal(r["hit_obstacle"], ho)
    np.testing.assert_array_equal(r["hit_agent"], ha)
    np.testing.assert_array_equal(r["hit_index"], first)


def test_block_simulated_stop_on_collision():
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=[[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]]), name="f")
    c = d.add(av.blocks.Constant([[1.0, 0.0], [1.0, 0.0]]), name="c")
    w = World([rectangle(2.0, -1.0, 3.0, 1.0)])
    cl = d.add(Collision(w, 2, footprint=Disc(0.5), period=0.01), name="col")
    stop = d.add(StopOnCollision(2), name="stop")
    d.connect(f.pose, cl.pose)
    d.connect(c.y, stop.cmd)
    d.connect(cl.collision, stop.collision)
    d.connect(stop.cmd, f.cmd)
    res = av.simulate(d, 3.0, dt=0.01, log=[cl.collision, f.pose, cl.hit_index])
    hit = res[cl.collision]
    assert hit.shape == (301, 2)
    k = int(np.argmax(hit[:, 0]))
    assert abs(res.t[k] - 1.5) <= 0.011  # front reaches x = 2 when the centre is at 1.5
    assert not hit[:, 1].any()
    assert res[cl.hit_index][-1].tolist() == [0, -1]
    x_end = res[f.pose][-1]
    assert 1.5 <= x_end[0, 0] <= 1.52 and abs(x_end[1, 0] - 3.0) < 1e-9


def test_block_errors():
    with pytest.raises(av.ParameterError):
        Collision("not a world", 3)
    with pytest.raises(av.ParameterError):
        Collision(World(), 3, footprint=Disc([0.1, 0.2]))
    with pytest.raises(av.ParameterError):
        Collision(World(), 3, input="velocity")


# ---------------------------------------------------------------- grid method
def _both(w, pose, fp, n=None, **kw):
    n = len(pose) if n is None else n
    g = Collision(w, n, footprint=fp, method="grid", **kw)
    s = Collision(w, n, footprint=fp, method="shapely", **kw)
    u = {"pose": np.asarray(pose, float)}
    return g.output(0.0, {}, u, np), s.output(0.0, {}, u, np)


PAC = PolygonFootprint([(1, 0), (-0.6, 0.6), (-0.2, 0), (-0.6, -0.6)])


@pytest.mark.parametrize("fp", [Disc(0.8), Rectangle(1.6, 0.8), PAC])
@pytest.mark.parametrize("margin", [0.0, 0.3])
def test_grid_method_equals_shapely_random(fp, margin):
    gen = np.random.default_rng(7)
    w = _random_world(gen)
    pose = np.c_[gen.uniform(0, 50, (300, 2)), gen.uniform(-np.pi, np.pi, 300)]
    a, b = _both(w, pose, fp, margin=margin)
    assert 20 < b["hit_obstacle"].sum() < 280 and b["hit_agent"].sum() > 5
    for k in b:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_grid_method_hand_cases():
    """The hand-built cases above through the grid method: touching, holes,
    exact circles, walls, per-agent radii."""
    donut = shapely.Polygon([(-5, -5), (5, -5), (5, 5), (-5, 5)],
                            holes=[[(-2, -2), (2, -2), (2, 2), (-2, 2)]])
    w = World([donut])
    a, _ = _both(w, [[0, 0], [1.5, 0], [1.49, 0], [3.5, 0], [0, -1.5]], Disc(0.5))
    assert a["hit_obstacle"].tolist() == [False, True, False, True, True]
    w = World([rectangle(10, 10, 11, 11), Circle((0, 0), 1.0), rectangle(-0.2, -0.2, 0.2, 0.2)])
    p = 1.5 * np.array([np.cos(0.0872665), np.sin(0.0872665)])
    a, _ = _both(w, [p * (1 - 1e-9), p * 1.0001, [20, 20]], Disc(0.5))
    assert a["hit_obstacle"].tolist() == [True, False, False]
    a, _ = _both(w, [[0, 0, 0], [10.5, 10.5, 0], [5, 5, 0]], Disc(0.1))
    assert a["hit_index"].tolist() == [1, 0, -1]
    a, _ = _both(w, [[1.5, 0, 0], [2.001, 0, 0]], Rectangle(1.0, 1.0))
    assert a["hit_obstacle"].tolist() == [True, False]
    w = World([], bounds=(0, 0, 10, 10), walls=True)
    a, _ = _both(w, [[0.4, 5], [5, 5], [5, 9.6], [5.0, 6.0]], Disc(0.5))
    assert a["hit_index"].tolist() == [0, -1, 3, -1]
    assert a["hit_agent_index"].tolist() == [-1, 3, -1, 1]
    a, _ = _both(World(), [[0, 0], [1.0, 0], [2.6, 0]], Disc([0.3, 0.7, 0.2]))
    assert a["hit_agent"].tolist() == [True, True, False]
    # a footprint swallowing a small obstacle, and one inside a big obstacle
    w = World([rectangle(-0.1, -0.1, 0.1, 0.1), rectangle(10, 10, 20, 20)])
    a, _ = _both(w, [[0, 0, 0.3], [15, 15, 0.0], [5, 5, 0]], Rectangle(1.0, 1.0))
    assert a["hit_index"].tolist() == [0, 1, -1]


def test_grid_margin_raised_later_rebuilds():
    w = World([SQUARE])
    c = Collision(w, 1, footprint=Disc(0.5), method="grid")
    u = {"pose": np.array([[0.3, 0.0, 0.0]])}
    assert not c.output(0.0, {}, u, np)["collision"][0]
    c.set_parameter("margin", 0.25)
    assert c.output(0.0, {}, u, np)["collision"][0]


@pytest.mark.jax
@pytest.mark.parametrize("fp", [Disc(0.8), Rectangle(1.6, 0.8)])
def test_grid_method_traced_equals_numpy(fp):
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from avblocks.core.compiled._jax import x64
    gen = np.random.default_rng(3)
    w = _random_world(gen)
    pose = np.c_[gen.uniform(0, 50, (200, 2)), gen.uniform(-np.pi, np.pi, 200)]
    c = Collision(w, 200, footprint=fp, capacity=16, method="grid")
    want = c.output(0.0, {}, {"pose": pose}, np)
    with x64(True):
        got = jax.jit(lambda p: c.output(0.0, {}, {"pose": p}, jnp))(pose)
    for k in want:
        np.testing.assert_array_equal(np.asarray(got[k]), want[k], err_msg=k)


@pytest.mark.jax
def test_shapely_method_refused_by_the_compiled_engine_by_name():
    pytest.importorskip("jax")
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=[[0.0, 0.0, 0.0]]), name="f")
    c = d.add(av.blocks.Constant([[1.0, 0.0]]), name="c")
    cl = d.add(Collision(World([SQUARE]), 1, method="shapely"), name="col")
    d.connect(c.y, f.cmd)
    d.connect(f.pose, cl.pose)
    with pytest.raises(Exception, match="col"):
        av.simulate(d, 1.0, dt=0.1, log=[cl.collision], backend="jax")
    assert Collision(World([SQUARE]), 1).traceable        # the default traces


@pytest.mark.jax
def test_traced_margin_beyond_the_grid_reach_is_reported():
    """Under JAX the edge grid is a static plan: a margin raised past its
    reach stops a compiled run with an error naming the block and the radius
    (never silent); within it the run goes through."""
    pytest.importorskip("jax")
    import avblocks as av
    pose = np.array([[0.3, 0.0, 0.0], [-3.0, 0.0, 0.0]])
    d = av.Diagram()
    src = d.add(av.blocks.Constant(pose), name="src")
    col = d.add(Collision(World([SQUARE]), 2, footprint=Disc(0.5), margin=0.1),
                name="col")                                     # grid reach 0.7
    d.connect(src.y, col.pose)
    run = av.compile(d, 0.2, dt=0.1, log=[col.collision])
    res = run(params={"col.margin": 0.2})                       # needs 0.7: fits
    assert res[col.collision][-1].tolist() == [True, False]
    with pytest.raises(av.SimulationError) as e:
        run(params={"col.margin": 0.3})                         # needs 0.8
    msg = str(e.value)
    assert "'col'" in msg and "radius 0.8" in msg and "built for 0.7" in msg
