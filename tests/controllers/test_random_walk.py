"""RandomWalk: interval distributions (KS tests), repeatability, boundaries."""

import numpy as np
import pytest
from scipy import stats

import avblocks as av
from avblocks.controllers.random_walk import Distribution, RandomWalk


def _run(rw, pose0, t_final, dt=0.05, seed=0):
    d = av.Diagram()
    veh = d.add(av.vehicles.Unicycle(pose0=pose0), name="veh")
    c = d.add(rw, name="rw")
    d.connect(veh.pose, c.pose)
    d.connect(c.cmd, veh.cmd)
    return av.simulate(d, t_final, dt=dt, seed=seed, log=[veh.pose, c.cmd, c.next_switch])


def _intervals(sched):
    out = []
    for col in sched.T:
        vals = col[np.r_[True, np.diff(col) != 0]]
        out.append(np.diff(vals))
    return np.concatenate(out), [col[np.r_[True, np.diff(col) != 0]] for col in sched.T]


@pytest.mark.parametrize("spec", [("exponential", 1.0), ("normal", 2.0, 0.4),
                                  ("uniform", 0.5, 2.5)])
def test_switching_intervals_follow_the_distribution(spec):
    n, dt = 60, 0.05
    rw = RandomWalk(n, interval=spec, speed=(0.2, 1.0))
    res = _run(rw, np.zeros((n, 3)), 40.0, dt=dt)
    tau, schedules = _intervals(res["rw.next_switch"])
    # drop each agent's last (still pending) interval: only completed ones
    tau = np.concatenate([np.diff(s)[:-1] for s in schedules])
    assert len(tau) > 400
    dist = Distribution.parse(spec).scipy()
    assert stats.kstest(tau, dist.cdf).pvalue > 0.01
    # a wrong distribution is rejected (the test has power)
    wrong = stats.expon(scale=1.3 * dist.mean())
    assert stats.kstest(tau, wrong.cdf).pvalue < 0.01
    # the speed really changes at the first step k with t_k >= scheduled time
    # (one switch per step), visible in the outputs at t_{k+1}
    v = res["rw.cmd"][:, :, 0]
    t = res.t
    for agent in range(5):
        changes = t[1:][np.diff(v[:, agent]) != 0]
        k, want = 0, [dt]                       # the first draw at t = 0
        for s in schedules[agent][1:]:
            k = max(int(np.ceil(round(s / dt, 9))), k + 1)
            want.append((k + 1) * dt)
        want = np.array(want)
        want = want[want <= t[-1] + 1e-9]
        np.testing.assert_allclose(changes, want, atol=1e-9)


def test_same_seed_same_run_other_seed_other_run():
    pose0 = np.random.default_rng(0).uniform(-1, 1, (8, 3))
    a = _run(RandomWalk(8), pose0, 5.0, seed=7)["veh.pose"]
    b = _run(RandomWalk(8), pose0, 5.0, seed=7)["veh.pose"]
    c = _run(RandomWalk(8), pose0, 5.0, seed=8)["veh.pose"]
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)


@pytest.mark.parametrize("boundary", ["reflect", "turn_back"])
def test_boundary_keeps_agents_inside(boundary):
    n = 30
    rng = np.random.default_rng(1)
    pose0 = np.column_stack([rng.uniform(-4, 4, (n, 2)), rng.uniform(-3, 3, n)])
    rw = RandomWalk(n, interval=("exponential", 5.0), speed=(0.8, 1.0), gain=4.0,
                    bounds=(-5, -5, 5, 5), boundary=boundary, margin=0.2)
    p = _run(rw, pose0, 60.0)["veh.pose"]
    assert np.abs(p[:, :, :2]).max() < 5.5
    assert np.abs(p[:, :, :2]).max() > 4.5          # they do reach the walls


def test_polygon_and_bad_parameters():
    tri = [[0, 0], [4, 0], [0, 4]]
    rw = RandomWalk(2, polygon=tri[::-1])           # clockwise is fine
    assert rw.region[0].shape == (3, 2)
    with pytest.raises(av.ParameterError, match="convex"):
        RandomWalk(2, polygon=[[0, 0], [4, 0], [1, 1], [0, 4]])
    with pytest.raises(av.ParameterError):
        RandomWalk(2, interval=("normal", 1.0, -1.0))
    with pytest.raises(av.ParameterError):
        RandomWalk(2, interval=("cauchy", 1.0))
