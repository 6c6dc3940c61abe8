"""Changing a numeric parameter mid-run changes the run exactly as an
independent computation predicts: closed forms (consensus decay, speed
limits), a second implementation (the go-to-goal law in plain NumPy), or a
restart from the states at the switch with the new value."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av

DT = 0.01


def _run(d, steps, switch=None, solver="euler", x0=None, t0=0.0):
    """Simulator stepped by hand; ``switch = (k, {path: value})`` applies
    before step k. Returns the simulator."""
    sim = av.Simulator(d, DT, solver, x0=x0, t0=t0)
    sim.init()
    for k in range(steps):
        if switch is not None and k == switch[0]:
            for p, v in switch[1].items():
                sim.set_param(p, v)
        sim.step()
    return sim


def test_consensus_gain_switch_changes_the_decay_rate():
    """Two agents, one edge: e = x1 - x2 obeys e' = -2 K e, so Euler gives
    e_n = (1 - 2 K dt)^m (1 - 4 K dt)^(n - m) e_0 with K then 2K at step m."""
    d = av.Diagram()
    f = d.add(av.vehicles.SingleIntegrator([[0.0, 0.0], [1.0, 2.0]]), name="f")
    c = d.add(av.controllers.Consensus(2, gain=1.5, adjacency=[[0, 1], [1, 0]]),
              name="cons")
    d.connect(f.position, c.position)
    d.connect(c.velocity, f.velocity)
    m, n, k = 40, 100, 1.5
    sim = _run(d, n, switch=(m, {"cons.gain": 2 * k}))
    p = sim.state("f", "position")
    e = p[0] - p[1]
    expect = (1 - 2 * k * DT) ** m * (1 - 4 * k * DT) ** (n - m) * np.array([-1.0, -2.0])
    np.testing.assert_allclose(e, expect, rtol=1e-12)
    # the mean is invariant whatever the gain
    np.testing.assert_allclose(p.mean(axis=0), [0.5, 1.0], rtol=1e-13)
    assert sim.param_changes == [(pytest.approx(m * DT), "cons.gain", 3.0)]


def _p2p_plain(p0, goal, d, gains, vmaxes, steps, m):
    """The go-to-goal law and unicycle, Euler, in plain NumPy (a second
    implementation); gain and v_max switch at step m."""
    pose = p0.copy()
    for k in range(steps):
        g, vm = (gains[0], vmaxes[0]) if k < m else (gains[1], vmaxes[1])
        th = pose[:, 2]
        c, s = np.cos(th), np.sin(th)
        ex = goal[:, 0] - pose[:, 0] - d * c
        ey = goal[:, 1] - pose[:, 1] - d * s
        wx, wy = g * ex, g * ey
        nrm = np.hypot(wx, wy)
        scale = np.minimum(1.0, vm / np.maximum(nrm, 1e-300))
        wx, wy = wx * scale, wy * scale
        v = c * wx + s * wy
        w = (-s * wx + c * wy) / d
        pose = pose + DT * np.column_stack([v * c, v * s, w])
    return pose


@pytest.mark.parametrize("path,new", [("drive.gain", 3.0), ("drive.v_max", 0.4)])
def test_point_to_point_gain_and_vmax_switch_match_plain_numpy(path, new):
    rng = np.random.default_rng(4)
    p0 = np.column_stack([rng.uniform(0, 2, (5, 2)), rng.uniform(-3, 3, 5)])
    goal = rng.uniform(0, 2, (5, 2))
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(p0), name="fleet")
    c = d.add(av.controllers.PointToPoint(goal[:, None, :], d=0.1, gain=0.8, v_max=1.0,
                                          radius=1e-6), name="drive")
    d.connect(f.pose, c.pose)
    d.connect(c.cmd, f.cmd)
    m, n = 50, 150
    sim = _run(d, n, switch=(m, {path: new}))
    gains = (0.8, new if path.endswith("gain") else 0.8)
    vmaxes = (1.0, new if path.endswith("v_max") else 1.0)
    ref = _p2p_plain(p0, goal, 0.1, gains, vmaxes, n, m)
    np.testing.assert_allclose(sim.state("fleet", "pose"), ref, rtol=1e-12, atol=1e-12)
    # and the switch did change the run
    ref_same = _p2p_plain(p0, goal, 0.1, (0.8, 0.8), (1.0, 1.0), n, m)
    assert np.abs(ref - ref_same).max() > 1e-3


def test_unicycle_speed_limit_switch_is_exact():
    """Constant command v = 1 along x: the limit 0.5 then 0.3 gives
    x_n = 0.5 dt m + 0.3 dt (n - m)."""
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0, 0.0]]), name="c")
    f = d.add(av.vehicles.Unicycle(np.zeros((1, 3)), v_max=0.5), name="f")
    d.connect(c.y, f.cmd)
    sim = _run(d, 100, switch=(30, {"f.v_max": 0.3}), solver="rk4")
    assert sim.state("f", "pose")[0, 0] == pytest.approx(0.5 * DT * 30 + 0.3 * DT * 70,
                                                         abs=1e-13)


def test_random_walk_speed_switch_shows_in_the_distance_per_step():
    """speed = (v, v) draws exactly v; after the switch to (w, w) each
    agent moves w dt per step (Euler, once a new speed has been drawn, at
    the next switch time: intervals of exactly one step here)."""
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(np.zeros((4, 3))), name="f")
    rw = d.add(av.controllers.RandomWalk(4, interval=("uniform", 0.0, 1e-9),
                                         speed=(0.7, 0.7), min_interval=DT),
               name="walk")
    d.connect(f.pose, rw.pose)
    d.connect(rw.cmd, f.cmd)
    sim = av.Simulator(d, DT, "euler")
    sim.init()
    steps = []
    for k in range(40):
        if k == 20:
            sim.set_param("walk.speed", [0.2, 0.2])
        p = sim.state("f", "pose")[:, :2].copy()
        sim.step()
        steps.append(np.hypot(*(sim.state("f", "pose")[:, :2] - p).T))
    steps = np.array(steps)
    np.testing.assert_allclose(steps[1:20], 0.7 * DT, rtol=1e-12)
    np.testing.assert_allclose(steps[21:], 0.2 * DT, rtol=1e-12)


def _restart_check(build, path, value, steps=80, m=30, solver="rk4"):
    """Run A switches ``path`` to ``value`` at step m; run B stops at m and
    restarts a fresh diagram built with the new value from the states at m.
    Both must agree bit for bit (states of every block)."""
    d = build()
    a = _run(d, steps, switch=(m, {path: value}), solver=solver)
    d1 = build()
    first = _run(d1, m, solver=solver)
    x0 = {f"{n}.{s}": v for n, x, b in zip(first.compiled.names, first.X,
                                          first.compiled.blocks)
          for s, v in x.items() if s not in b.random_states}
    d2 = build()
    d2.build().set_param(path, value)
    b = _run(d2, steps - m, solver=solver, x0=x0)
    for (n, xa), xb in zip(zip(a.compiled.names, a.X), b.X):
        for s in xa:
            np.testing.assert_array_equal(np.asarray(xa[s]), np.asarray(xb[s]),
                                          err_msg=f"{n}.{s}")
    return a


def _leader_follower():
    d = av.Diagram()
    p0 = np.array([[0.0, 0, 0], [-1.0, 0.5, 0.3], [-2.0, -0.4, -0.2]])
    fleet = d.add(av.vehicles.Unicycle(p0), name="fleet")
    lead = d.add(av.blocks.Constant(np.tile([[0.5, 0.1]], (3, 1))), name="lead")
    lf = d.add(av.controllers.LeaderFollower([-1, 0, 1], l_ref=1.0, alpha_ref=0.2,
                                             k_l=1.0, k_alpha=1.0), name="follow")
    d.connect(fleet.pose, lf.pose)
    d.connect(lead.y, lf.cmd_in)
    d.connect(lf.cmd, fleet.cmd)
    return d


def _flock():
    rng = np.random.default_rng(2)
    d = av.Diagram()
    ag = d.add(av.vehicles.DoubleIntegrator(rng.uniform(0, 3, (6, 2)),
                                            velocity0=rng.normal(0, 0.3, (6, 2))),
               name="agents")
    fl = d.add(av.controllers.Flocking(6, 1.0, adjacency=np.ones((6, 6))), name="flock")
    d.connect(ag.position, fl.position)
    d.connect(ag.velocity, fl.velocity)
    d.connect(fl.accel, ag.accel)
    return d


@pytest.mark.parametrize("build,path,value", [
    (_leader_follower, "follow.k_l", 3.0),
    (_leader_follower, "follow.k_alpha", 0.3),
    (_flock, "flock.c1", 2.5),
    (_flock, "flock.c2", 0.2),
])
def test_switch_equals_restart_with_the_new_value(build, path, value):
    a = _restart_check(build, path, value)
    # and the value mattered: a run without the switch ends elsewhere
    plain = _run(build(), 80, solver="rk4")
    assert max(np.abs(np.asarray(xa[s]) - np.asarray(xp[s])).max()
               for xa, xp in zip(a.X, plain.X) for s in xa) > 1e-4
