"""RangeSensor: closed-form distances to axis-aligned and rotated walls,
circles and agents; cross-check against shapely ray intersections."""

import numpy as np
import pytest
import shapely

import avblocks as av
from avblocks.environment import Circle, RangeSensor, World, cast_rays, ray_angles, rectangle


def test_ray_angles():
    np.testing.assert_allclose(ray_angles(4), [0, np.pi / 2, np.pi, 1.5 * np.pi])
    np.testing.assert_allclose(ray_angles(3, np.pi / 2), [-np.pi / 4, 0, np.pi / 4])
    assert ray_angles(1, 1.0).tolist() == [0.0]


def test_axis_aligned_walls():
    w = World([rectangle(3, -10, 4, 10), rectangle(-10, 2, 10, 2.5)])
    ang = ray_angles(9, np.pi / 2)  # -45 .. 45 degrees
    r = cast_rays(w, np.zeros((1, 3)), ang, 50.0)[0]
    # right wall at x = 3 (3 / cos) unless the top wall y = 2 comes first (2 / sin)
    with np.errstate(divide="ignore"):
        expect = np.minimum(3 / np.cos(ang), np.where(ang > 0, 2 / np.sin(ang), np.inf))
    np.testing.assert_allclose(r, expect, rtol=1e-12)
    # looking along -x: nothing within 50 m
    r = cast_rays(w, np.array([[0, 0, np.pi]]), [0.0], 50.0)
    assert r.tolist() == [[50.0]]


def _rotated_wall(dist, alpha, thick=1.0, half=30.0, origin=(0, 0)):
    nrm = np.array([np.cos(alpha), np.sin(alpha)])
    tan = np.array([-np.sin(alpha), np.cos(alpha)])
    o = np.asarray(origin, float)
    near, far = o + dist * nrm, o + (dist + thick) * nrm
    return [near - half * tan, near + half * tan, far + half * tan, far - half * tan]


@pytest.mark.parametrize("alpha,heading,origin", [(0.3, 0.1, (0, 0)), (2.0, 1.5, (4, -2)),
                                                  (-2.5, -2.0, (-1, 7))])
def test_rotated_wall_closed_form(alpha, heading, origin):
    dist = 2.5
    w = World([_rotated_wall(dist, alpha, origin=origin)])
    ang = ray_angles(32, np.pi)
    r = cast_rays(w, np.array([[*origin, heading]]), ang, 20.0)[0]
    c = np.cos(heading + ang - alpha)
    with np.errstate(divide="ignore"):
        expect = np.where(c > 0, dist / c, np.inf)
    expect = np.minimum(expect, 20.0)
    np.testing.assert_allclose(r, expect, rtol=1e-10, atol=1e-12)


def test_circles_and_agents():
    w = World([Circle((5.0, 0.0), 1.0)])
    beta = np.array([0.0, 0.1, 0.2, 0.25])
    r = cast_rays(w, np.zeros((1, 3)), beta, 10.0)[0]
    disc = 1 - 25 * np.sin(beta) ** 2
    expect = np.where(disc >= 0, 5 * np.cos(beta) - np.sqrt(np.maximum(disc, 0)), 10.0)
    np.testing.assert_allclose(r, expect, rtol=1e-12)
    # other agents as discs of radius 0.5; own disc ignored
    pose = np.array([[0, 0, 0.0], [3, 0, 0.0]])
    r = cast_rays(None, pose, [0.0, np.pi], 10.0, agent_radius=0.5)
    assert r.tolist() == [[2.5, 10.0], [10.0, 2.5]]
    r = cast_rays(w, pose, [0.0, np.pi], 10.0, agent_radius=0.5)
    assert r.tolist() == [[2.5, 10.0], [1.0, 2.5]]


def test_random_against_shapely():
    gen = np.random.default_rng(5)
    obs = [shapely.MultiPoint(c + gen.normal(0, 1.0, (6, 2))).convex_hull
           for c in gen.uniform(0, 30, (40, 2))]
    w = World(obs)
    pose = np.c_[gen.uniform(0, 30, (60, 2)), gen.uniform(-np.pi, np.pi, 60)]
    ang = ray_angles(16)
    R = 8.0
    r = cast_rays(w, pose, ang, R)
    bound = shapely.union_all([g.boundary for g in w.geoms])
    for i in range(0, 60, 3):  # reference check on a subset
        for a, got in zip(ang, r[i]):
            phi = pose[i, 2] + a
            end = pose[i, :2] + R * np.array([np.cos(phi), np.sin(phi)])
            ray = shapely.LineString([pose[i, :2], end])
            hit = ray.intersection(bound)
            pts = shapely.get_coordinates(hit)
            exp = R if len(pts) == 0 else min(R, np.min(np.hypot(*(pts - pose[i, :2]).T)))
            assert got == pytest.approx(exp, abs=1e-9)


def test_block_noise_and_simulation():
    w = World([rectangle(3, -10, 4, 10)])
    s = RangeSensor(w, 1, n_rays=1, fov=0.1, max_range=10, noise_std=0.1, period=0.01)
    d = av.Diagram()
    p = d.add(av.blocks.Constant(np.zeros((1, 3))), name="p")
    rs = d.add(s, name="rs")
    d.connect(p.y, rs.pose)
    res = av.simulate(d, 20.0, dt=0.01, log=[rs.ranges], seed=1)
    z = res[rs.ranges][:, 0, 0]
    assert abs(z.mean() - 3.0) < 4 * 0.1 / np.sqrt(len(z))
    assert abs(z.std() - 0.1) < 0.01
    again = av.simulate(d, 20.0, dt=0.01, log=[rs.ranges], seed=1)
    np.testing.assert_array_equal(again[rs.ranges][:, 0, 0], z)
    # rays that hit nothing stay at max_range
    s2 = RangeSensor(w, 1, n_rays=4, max_range=10, noise_std=0.5)
    y = s2.output(0.0, s2.initial_state(), {"pose": np.zeros((1, 3))}, np)
    assert y["ranges"][0, 1:].tolist() == [10.0, 10.0, 10.0]


def test_errors():
    with pytest.raises(av.ParameterError):
        RangeSensor(World(), 2, max_range=0)
    with pytest.raises(av.ParameterError):
        RangeSensor(World(), 2, fov=7.0)
    with pytest.raises(av.ParameterError):
        RangeSensor(World(), 2, agent_radius=[1, 2, 3])


# ---------------------------------------------------------------- grid method
def _concave_world(gen, m=30, size=30.0):
    obs = []
    for k in range(m):
        c = gen.uniform(0, size, 2)
        if k % 4 == 0:
            obs.append(Circle(c, gen.uniform(0.3, 1.5)))
            continue
        a = np.sort(gen.uniform(0, 2 * np.pi, 9))
        r = gen.uniform(0.4, 2.5, 9)                      # star: concave
        obs.append(np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a)])
    obs.append(shapely.Polygon([(10, 10), (20, 10), (20, 20), (10, 20)],
                               [[(12, 12), (18, 12), (18, 18), (12, 18)]]))
    return World(obs, bounds=(0, 0, size, size), walls=True)


@pytest.mark.parametrize("agents", [None, 0.4])
def test_grid_method_equals_shapely(agents):
    gen = np.random.default_rng(11)
    w = _concave_world(gen)
    n = 80
    pose = np.c_[gen.uniform(-1, 31, (n, 2)), gen.uniform(-np.pi, np.pi, n)]
    pose[:3, :2] = [[15.0, 15.0], [12.0, 15.0], [11.0, 11.0]]   # in the hole, on its edge
    kw = dict(n_rays=24, max_range=6.0, agent_radius=agents)
    g = RangeSensor(w, n, method="grid", **kw)
    s = RangeSensor(w, n, method="shapely", **kw)
    a = g.output(0.0, {}, {"pose": pose}, np)["ranges"]
    b = s.output(0.0, {}, {"pose": pose}, np)["ranges"]
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    assert 0.2 < np.mean(a < 6.0) < 0.9                    # rays do hit things
    if agents is not None:
        return
    # independent truth on a subset: shapely ray / boundary intersections
    # (circles as 1024-gons: within 2e-5 m of the true circle)
    geoms = [shapely.Point(w.circle_center[k]).buffer(w.circle_radius[k], quad_segs=256)
             if w.is_circle[k] else w.geoms[k] for k in range(w.n_obstacles)]
    bound = shapely.union_all([g_.boundary for g_ in geoms])
    for i in range(0, n, 7):
        for k, ang in enumerate(g.angles):
            phi = pose[i, 2] + ang
            end = pose[i, :2] + 6.0 * np.array([np.cos(phi), np.sin(phi)])
            pts = shapely.get_coordinates(
                shapely.LineString([pose[i, :2], end]).intersection(bound))
            exp = min([6.0, *np.hypot(*(pts - pose[i, :2]).T)])
            assert a[i, k] == pytest.approx(exp, abs=1e-4)


def test_grid_method_max_range_raised_later():
    w = World([rectangle(5, -1, 6, 1)])
    s = RangeSensor(w, 1, n_rays=1, fov=0.1, max_range=3.0, method="grid")
    y = s.output(0.0, {}, {"pose": np.zeros((1, 3))}, np)["ranges"]
    assert y.tolist() == [[3.0]]
    s.set_parameter("max_range", 8.0)
    y = s.output(0.0, {}, {"pose": np.zeros((1, 3))}, np)["ranges"]
    assert y.tolist() == [[5.0]]


@pytest.mark.jax
def test_grid_method_traced_equals_numpy():
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from avblocks.core.compiled._jax import x64
    gen = np.random.default_rng(12)
    w = _concave_world(gen)
    n = 100
    pose = np.c_[gen.uniform(0, 30, (n, 2)), gen.uniform(-np.pi, np.pi, n)]
    s = RangeSensor(w, n, n_rays=16, max_range=5.0, agent_radius=0.3, capacity=64,
                    method="grid")
    want = s.output(0.0, {}, {"pose": pose}, np)["ranges"]
    with x64(True):
        got = jax.jit(lambda p: s.output(0.0, {}, {"pose": p}, jnp)["ranges"])(pose)
    np.testing.assert_allclose(np.asarray(got), want, rtol=0, atol=1e-12)


@pytest.mark.jax
def test_block_compiled_run_equals_numpy():
    """A unicycle circling among obstacles with a range sensor, simulated by
    both engines: equal scans."""
    pytest.importorskip("jax")
    gen = np.random.default_rng(13)
    w = _concave_world(gen)

    def build():
        d = av.Diagram()
        p0 = np.array([[3.0, 3.0, 0.0], [27.0, 27.0, np.pi], [15.0, 15.0, 1.0]])
        f = d.add(av.vehicles.Unicycle(pose0=p0), name="f")
        c = d.add(av.blocks.Constant([[1.0, 0.3], [1.0, -0.2], [0.5, 0.5]]), name="c")
        rs = d.add(RangeSensor(w, 3, n_rays=12, max_range=5.0, agent_radius=0.3,
                               period=0.05), name="rs")
        d.connect(c.y, f.cmd)
        d.connect(f.pose, rs.pose)
        return d

    a = av.simulate(build(), 5.0, dt=0.05, log=["rs.ranges"])
    b = av.simulate(build(), 5.0, dt=0.05, log=["rs.ranges"], backend="jax")
    np.testing.assert_allclose(b["rs.ranges"], a["rs.ranges"], rtol=0, atol=1e-9)
    assert np.mean(a["rs.ranges"] < 5.0) > 0.1


@pytest.mark.jax
def test_grid_ranges_gradient_equals_finite_differences():
    """d(sum of ranges)/d(pose) through the traced scan (walls, a concave
    polygon, a circle, other agents) equals central differences of the
    NumPy scan: no NaN from the padded or missed entries."""
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from avblocks.core.compiled._jax import x64
    w = World([rectangle(2, -1, 3, 1), Circle((-2, 0), 0.5),
               [(0, 3), (1, 4), (0.5, 3.5), (-1, 4)]])
    s = RangeSensor(w, 3, n_rays=16, max_range=4.0, agent_radius=0.3, method="grid")
    pose = np.array([[0, 0, 0.1], [0.5, 0.5, 1.0], [-0.5, 1, 2]])

    def total(p, xp):
        return xp.sum(s.output(0.0, {}, {"pose": p}, xp)["ranges"])

    with x64(True):
        g = np.asarray(jax.grad(lambda p: total(p, jnp))(jnp.asarray(pose)))
    h = 1e-6
    fd = np.zeros_like(pose)
    for i in range(3):
        for j in range(3):
            e = np.zeros_like(pose)
            e[i, j] = h
            fd[i, j] = (total(pose + e, np) - total(pose - e, np)) / (2 * h)
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-6)


@pytest.mark.jax
def test_noisy_scan_compiled():
    """Noise under the compiled engine: its own stream (jax.random), the
    same statistics as the NumPy test above (mean 3 m, std 0.1 m)."""
    pytest.importorskip("jax")
    w = World([rectangle(3, -10, 4, 10)])
    d = av.Diagram()
    p = d.add(av.blocks.Constant(np.zeros((1, 3))), name="p")
    rs = d.add(RangeSensor(w, 1, n_rays=1, fov=0.1, max_range=10, noise_std=0.1,
                           period=0.01), name="rs")
    d.connect(p.y, rs.pose)
    z = av.simulate(d, 20.0, dt=0.01, log=[rs.ranges], seed=1, backend="jax")[rs.ranges]
    z = z[:, 0, 0]
    assert abs(z.mean() - 3.0) < 4 * 0.1 / np.sqrt(len(z))
    assert abs(z.std() - 0.1) < 0.01
    assert len(np.unique(z)) > 1000                       # a fresh draw per scan
