"""The memo that lets blocks share a pure computation on one array
(avblocks.core.memo): values, identity semantics, and the trig the
unicycle and the go-to-goal law share inside a simulator."""

import math

import numpy as np

import avblocks as av
from avblocks.core import memo


def _count(fn):
    calls = []

    def wrapped(a, xp):
        calls.append(a)
        return fn(a, xp)
    return wrapped, calls


def test_outside_a_simulator_it_just_calls():
    f, calls = _count(lambda a, xp: a * 2)
    a = np.arange(3.0)
    assert np.array_equal(memo.shared(f, a, np), 2 * a)
    memo.shared(f, a, np)
    assert len(calls) == 2


def test_same_object_once_equal_copy_again():
    f, calls = _count(lambda a, xp: a + 1)
    a = np.arange(4.0)
    with memo.active(memo.Memo()) as m:
        r1 = memo.shared(f, a, np)
        r2 = memo.shared(f, a, np)
        assert r1 is r2 and len(calls) == 1 and m.hits == 1
        b = a.copy()                        # equal values, another object
        memo.shared(f, b, np)
        assert len(calls) == 2
    memo.shared(f, a, np)                    # memo no longer active
    assert len(calls) == 3


def test_bounded_and_evicts_oldest():
    f, calls = _count(lambda a, xp: a.sum())
    arrays = [np.full(2, float(i)) for i in range(40)]
    with memo.active(memo.Memo()) as m:
        for a in arrays:
            memo.shared(f, a, np)
        assert len(m.entries) <= memo._SIZE
        memo.shared(f, arrays[-1], np)      # newest is kept
        assert len(calls) == 40
        memo.shared(f, arrays[0], np)       # oldest was forgotten
        assert len(calls) == 41


def _w1(n=50, seed=3):
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(0, 20, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    goal = rng.uniform(0, 20, (n, 2))
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    c = d.add(av.controllers.PointToPoint(goal[:, None, :], d=0.1, gain=1.0, v_max=1.0),
              name="drive")
    d.connect(f.pose, c.pose)
    d.connect(c.cmd, f.cmd)
    return d, f, p0, goal


def test_unicycle_and_controller_take_the_heading_trig_once_per_step():
    d, f, _, _ = _w1()
    sim = av.Simulator(d, 0.01, "euler")
    sim.init()
    for _ in range(5):                     # warm: the output at t_k is cached
        sim.step()
    h0 = sim._memo.hits
    m0 = sim._memo.misses
    for _ in range(100):
        sim.step()
    # per step: the vehicle's wrapped pose and its trig are computed once
    # (misses, at the outputs of t_k+1) and reused once each (hits, by the
    # derivative at the next step)
    assert sim._memo.misses - m0 == 200
    assert sim._memo.hits - h0 == 200


def test_diagram_equals_the_hand_fused_loop():
    """Second implementation: the go-to-goal law and Euler step written as one
    loop (no blocks, no wrapping); the diagram must agree to round-off, with
    headings that leave (-pi, pi] during the run."""
    n, dt, steps = 50, 0.01, 800
    d, f, p0, goal = _w1(n)
    res = av.simulate(d, steps * dt, dt=dt, solver="euler", log=[f.pose], progress=False)
    pose = p0.copy()
    for _ in range(steps):
        th = pose[:, 2]
        c, s = np.cos(th), np.sin(th)
        ex = goal[:, 0] - pose[:, 0] - 0.1 * c
        ey = goal[:, 1] - pose[:, 1] - 0.1 * s
        nrm = np.hypot(ex, ey)
        k = np.minimum(1.0, 1.0 / nrm)
        wx, wy = k * ex, k * ey
        v, w = c * wx + s * wy, (c * wy - s * wx) / 0.1
        pose = pose + dt * np.column_stack([v * c, v * s, w])
    assert np.abs(pose[:, 2]).max() > math.pi      # the wrap path was exercised
    got = res[f.pose][-1]
    assert np.allclose(got[:, :2], pose[:, :2], atol=1e-9, rtol=0)
    wrapped = pose[:, 2] - 2 * np.pi * np.ceil((pose[:, 2] - np.pi) / (2 * np.pi))
    assert np.allclose(got[:, 2], wrapped, atol=1e-9, rtol=0)


def test_compute_once_under_jax_is_exact_and_computed_once():
    import os

    import pytest
    if os.environ.get("CI"):
        import jax
    else:
        jax = pytest.importorskip("jax")
    jnp = jax.numpy
    from avblocks.utility.angles import heading_trig

    def two_users(pose):
        c, s = heading_trig(pose, jnp)
        # two results of different shapes: XLA would fuse the trig into each
        return jnp.stack([c * 2.0, s - 1.0, c * s], -1), (c * c + s * s) > 0.5

    with jax.enable_x64(True):
        pose = jnp.asarray(np.random.default_rng(0).uniform(-9, 9, (200, 3)))
        a, b = jax.jit(two_users)(pose)
        th = np.asarray(pose)[:, 2]
        assert np.allclose(np.asarray(a)[:, 0], 2 * np.cos(th), rtol=0, atol=1e-15)
        assert np.allclose(np.asarray(a)[:, 1], np.sin(th) - 1, rtol=0, atol=1e-15)
        assert np.asarray(b).all()
        if jax.default_backend() == "cpu":
            hlo = jax.jit(two_users).lower(pose).compile().as_text()
            assert hlo.count("cosine(") == 1 and hlo.count(" sine(") == 1
