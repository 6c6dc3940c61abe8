"""The demo diagram (unicycles + point-to-point) against independent truth,
and traced under JAX to prove the blocks are pure."""

import numpy as np
import pytest

import avblocks as av


def test_unicycle_closed_form_circle():
    v, w = 1.5, 0.4
    p0 = np.array([[1.0, -2.0, 0.3], [0.0, 0.0, -2.0]])
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=p0), name="f")
    c = d.add(av.blocks.Constant(np.tile([v, w], (2, 1))), name="c")
    d.connect(c.y, f.cmd)
    res = av.simulate(d, 10.0, dt=0.01, log=[f.pose])
    t = res.t[:, None]
    th = p0[:, 2] + w * t
    x = p0[:, 0] + v / w * (np.sin(th) - np.sin(p0[:, 2]))
    y = p0[:, 1] - v / w * (np.cos(th) - np.cos(p0[:, 2]))
    P = res[f.pose]
    assert np.allclose(P[..., 0], x, atol=1e-9)
    assert np.allclose(P[..., 1], y, atol=1e-9)
    assert np.allclose(np.cos(P[..., 2]), np.cos(th), atol=1e-9)
    assert np.all((P[..., 2] > -np.pi) & (P[..., 2] <= np.pi))


def demo(n=12, seed=0):
    rng = np.random.default_rng(seed)
    p0 = av.utility.random_poses(n, area=(20, 20), seed=seed)
    counts = rng.integers(1, 4, n)
    wps = [rng.uniform(0, 20, (k, 2)) for k in counts]
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    drive = d.add(av.controllers.PointToPoint(wps, d=0.1, gain=1.0, v_max=2.0,
                                              radius=0.2), name="drive")
    d.connect(fleet.pose, drive.pose)
    d.connect(drive.cmd, fleet.cmd)
    return d, fleet, drive, wps


def test_point_to_point_reaches_every_waypoint():
    d, fleet, drive, wps = demo()
    res = av.simulate(d, 60.0, dt=0.02, log=[fleet.pose, drive.done])
    P = res[fleet.pose]
    point = P[..., :2] + 0.1 * np.stack([np.cos(P[..., 2]), np.sin(P[..., 2])], -1)
    for i, w in enumerate(wps):
        for g in w:  # the controlled point came within the radius of each one
            assert np.min(np.linalg.norm(point[:, i] - g, axis=-1)) <= 0.2 + 1e-9
        # and holds at the last one
        assert np.linalg.norm(point[-1, i] - w[-1]) < 0.05
    assert res[drive.done][-1].all()


def test_point_to_point_law_is_feedback_linearization():
    # the off-axis point moves exactly with velocity K (g - p) (unsaturated)
    rng = np.random.default_rng(2)
    pose = np.column_stack([rng.normal(size=(9, 2)), rng.uniform(-3, 3, 9)])
    goal = rng.normal(size=(9, 2))
    d, K = 0.3, 0.7
    cmd = av.controllers.point_to_point_law(pose, goal, d, K, np.inf)
    v, w = cmd[:, 0], cmd[:, 1]
    th = pose[:, 2]
    pdot = np.column_stack([v * np.cos(th) - d * w * np.sin(th),
                            v * np.sin(th) + d * w * np.cos(th)])
    p = pose[:, :2] + d * np.column_stack([np.cos(th), np.sin(th)])
    assert np.allclose(pdot, K * (goal - p), atol=1e-12)


def test_point_to_point_law_saturates_and_its_numpy_path_equals_the_generic_one():
    """The NumPy path (in-place buffers) against the expressions every other
    array namespace runs (a namespace that is not ``numpy`` itself), bit for
    bit; and the controlled point's speed is min(K |e|, v_max)."""
    import types
    generic = types.SimpleNamespace(**{k: getattr(np, k) for k in dir(np)
                                       if not k.startswith("_")})
    rng = np.random.default_rng(5)
    n = 40
    pose = np.column_stack([rng.normal(0, 5, (n, 2)), rng.uniform(-9, 9, n)])
    goal = rng.normal(0, 5, (n, 2))
    d, gain, vmax = 0.25, rng.uniform(0.2, 2.0, n), rng.uniform(0.1, 3.0, n)
    cmd, near = av.controllers.point_to_point_law(pose, goal, d, gain, vmax, radius=1.5)
    cmd_g, near_g = av.controllers.point_to_point_law(pose, goal, d, gain, vmax,
                                                      xp=generic, radius=1.5)
    assert np.array_equal(cmd, cmd_g) and np.array_equal(near, near_g)
    th = pose[:, 2]
    p = pose[:, :2] + d * np.column_stack([np.cos(th), np.sin(th)])
    e = np.linalg.norm(goal - p, axis=1)
    v, w = cmd[:, 0], cmd[:, 1]
    pdot = np.column_stack([v * np.cos(th) - d * w * np.sin(th),
                            v * np.sin(th) + d * w * np.cos(th)])
    assert np.allclose(np.linalg.norm(pdot, axis=1), np.minimum(gain * e, vmax),
                       rtol=1e-12, atol=1e-12)
    assert np.array_equal(near, e <= 1.5)
    assert (e > 1.5).any() and (e <= 1.5).any()
    assert (gain * e > vmax).any() and (gain * e < vmax).any()   # both regimes


@pytest.mark.jax
def test_demo_traced_under_jax_matches_numpy():
    pytest.importorskip("jax")
    from avblocks.core.jax_backend import simulate_jax

    d, fleet, drive, _ = demo(n=10)
    ref = av.simulate(d, 10.0, dt=0.01, log=[fleet.pose, drive.cmd])
    d2, fleet2, drive2, _ = demo(n=10)
    got = simulate_jax(d2, 10.0, dt=0.01, log=[fleet2.pose, drive2.cmd])
    assert np.max(np.abs(got["fleet.pose"] - ref[fleet.pose])) < 1e-9
    assert np.max(np.abs(got["drive.cmd"] - ref[drive.cmd])) < 1e-9
