"""Consensus, displacement formation, cyclic pursuit, flocking, holonomic P2P, off-axis map."""

import math

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import (
    Consensus,
    CyclicPursuit,
    DisplacementFormation,
    Flocking,
    HolonomicPointToPoint,
    HolonomicToUnicycle,
    OffAxisPoint,
    bump,
    order_parameter,
    sigma_norm,
)
from avblocks.controllers._graph import adjacency_to_neighbors, laplacian
from avblocks.environment.neighbors import radius_neighbors


def _ring_adjacency(n):
    a = np.zeros((n, n))
    i = np.arange(n)
    a[i, (i + 1) % n] = a[(i + 1) % n, i] = 1.0
    a[0, n // 2] = a[n // 2, 0] = 2.0          # a weighted chord
    return a


def _single(ctl, x0, t_final, dt=0.02, **kw):
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(x0), name="ag")
    c = d.add(ctl, name="c")
    d.connect(ag.y, c.position)
    d.connect(c.velocity, ag.u)
    t_final = round(t_final / dt) * dt      # a whole number of steps
    return av.simulate(d, t_final, dt=dt, log=[ag.y], **kw)["ag.y"]


def test_consensus_reaches_average_at_connectivity_rate():
    n = 12
    a = _ring_adjacency(n)
    x0 = np.random.default_rng(0).uniform(-5, 5, (n, 2))
    lam2 = np.sort(np.linalg.eigvalsh(laplacian(a)))[1]
    t_final = 8.0 / lam2
    x = _single(Consensus(n, adjacency=a, gain=1.0), x0, t_final, dt=0.05)
    np.testing.assert_allclose(x.mean(axis=1), np.broadcast_to(x0.mean(0), (len(x), 2)),
                               atol=1e-10)
    spread0 = np.abs(x0 - x0.mean(0)).max()
    assert np.abs(x[-1] - x0.mean(0)).max() < 3 * spread0 * math.exp(-8.0)
    # the independent linear solution x(t) = expm(-L t) x0
    from scipy.linalg import expm
    np.testing.assert_allclose(x[-1], expm(-laplacian(a) * t_final) @ x0, atol=1e-6)


def test_consensus_port_and_radius_modes_agree_with_laplacian():
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 4, (30, 2))
    idx, dist = radius_neighbors(p, 1.0, 29)
    a = np.zeros((30, 30))
    rows = np.repeat(np.arange(30), idx.shape[1])
    ok = idx.ravel() >= 0
    a[rows[ok], idx.ravel()[ok]] = 1.0
    want = -laplacian(a) @ p
    c_port = Consensus(30)
    got = c_port.output(0, {}, {"position": p, "neighbors": idx}, np)["velocity"]
    np.testing.assert_allclose(got, want, atol=1e-12)
    c_rad = Consensus(30, radius=1.0, k_max=29)
    np.testing.assert_allclose(c_rad.output(0, {}, {"position": p}, np)["velocity"], want,
                               atol=1e-12)
    idx2, w2 = adjacency_to_neighbors(a, 30, "t")
    assert idx2.shape[1] == int(a.sum(1).max())


def test_consensus_with_neighbors_port_in_a_diagram():
    n = 6
    idx = np.stack([(np.arange(n) - 1) % n, (np.arange(n) + 1) % n], axis=1)
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(np.arange(2 * n, dtype=float).reshape(n, 2)), name="ag")
    nb = d.add(av.blocks.Constant(idx.astype(np.int64)), name="nb")
    c = d.add(Consensus(n), name="c")
    d.connect(ag.y, c.position)
    d.connect(nb.y, c.neighbors)
    d.connect(c.velocity, ag.u)
    x = av.simulate(d, 30.0, dt=0.05, log=[ag.y])[ag.y]
    np.testing.assert_allclose(x[-1], np.broadcast_to([5.0, 6.0], (n, 2)), atol=1e-6)


def test_displacement_formation_reaches_shape():
    n = 8
    ang = 2 * np.pi * np.arange(n) / n
    c = 3 * np.column_stack([np.cos(ang), np.sin(ang)])
    x0 = np.random.default_rng(2).uniform(-4, 4, (n, 2))
    x = _single(DisplacementFormation(c, adjacency=_ring_adjacency(n)), x0, 60.0, dt=0.05)
    shift = (x0 - c).mean(0)
    np.testing.assert_allclose(x[-1], c + shift, atol=1e-4)


def test_cyclic_pursuit_circle_and_rendezvous():
    n = 6
    x0 = np.random.default_rng(3).uniform(-3, 3, (n, 2))
    x = _single(CyclicPursuit(n, angle=0.0), x0, 40.0, dt=0.05)
    np.testing.assert_allclose(x[-1], np.broadcast_to(x0.mean(0), (n, 2)), atol=1e-4)
    x = _single(CyclicPursuit(n, angle=np.pi / n), x0, 80.0, dt=0.05)
    rel = x[-1] - x[-1].mean(0)
    r = np.hypot(rel[:, 0], rel[:, 1])
    assert r.min() > 0.1 and np.ptp(r) < 1e-3 * r.mean()       # a regular polygon
    gaps = np.linalg.norm(rel - np.roll(rel, -1, axis=0), axis=1)
    assert np.ptp(gaps) < 1e-3 * gaps.mean()


def test_sigma_norm_and_bump():
    z = np.array([[3.0, 4.0]])
    np.testing.assert_allclose(sigma_norm(z, 0.1), (math.sqrt(1 + 0.1 * 25) - 1) / 0.1)
    s = np.array([0.0, 0.1, 0.2, 0.6, 1.0, 1.5])
    np.testing.assert_allclose(bump(s, 0.2), [1, 1, 1, 0.5, 0, 0], atol=1e-12)


def test_flocking_aligns_and_keeps_lattice_distance():
    n, dd = 30, 1.0
    rng = np.random.default_rng(4)
    q0 = rng.uniform(0, 4.0, (n, 2))
    p0 = rng.uniform(-1, 1, (n, 2))
    fl = Flocking(n, dd, c1=3.0, gamma=True, target=[2.0, 2.0], target_velocity=[1.0, 0.0],
                  c1_gamma=0.05, c2_gamma=0.4, neighbors="internal", k_max=12)
    d = av.Diagram()
    pos = d.add(av.blocks.Integrator(q0), name="pos")
    vel = d.add(av.blocks.Integrator(p0), name="vel")
    f = d.add(fl, name="f")
    d.connect(vel.y, pos.u)
    d.connect(pos.y, f.position)
    d.connect(vel.y, f.velocity)
    d.connect(f.accel, vel.u)
    res = av.simulate(d, 40.0, dt=0.02, log=[pos.y, vel.y], log_every=10)
    p, q = res[vel.y], res[pos.y]
    assert order_parameter(p0) < 0.5
    assert order_parameter(p[-1]) > 0.95
    idx, dist = radius_neighbors(q[-1], fl.r, n - 1)
    nearest = dist[:, 0]
    assert np.all(np.isfinite(nearest))
    assert np.all(np.abs(nearest - dd) < 0.1 * dd)      # an alpha-lattice
    within = dist[np.isfinite(dist)]
    assert abs(within.mean() - dd) < 0.05 * dd


def test_holonomic_point_to_point_2d_and_3d():
    wps = [[[2.0, 0.0], [2.0, 2.0]], [[-1.0, -1.0]]]
    ctl = HolonomicPointToPoint(wps, gain=2.0, v_max=1.0, radius=0.05)
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(np.zeros((2, 2))), name="ag")
    c = d.add(ctl, name="c")
    d.connect(ag.y, c.position)
    d.connect(c.velocity, ag.u)
    res = av.simulate(d, 8.0, dt=0.01, log=[ag.y, c.done, c.velocity])
    np.testing.assert_allclose(res[ag.y][-1], [[2, 2], [-1, -1]], atol=1e-3)
    assert res[c.done][-1].all()
    assert np.linalg.norm(res[c.velocity], axis=-1).max() <= 1.0 + 1e-12
    # straight line at v_max while saturated: x(1) = 1
    np.testing.assert_allclose(res[ag.y][100, 0], [1.0, 0.0], atol=1e-9)
    c3 = HolonomicPointToPoint([[1.0, 2.0, 3.0]], n=4, gain=0.5, v_max=10.0)
    out = c3.output(0, c3.initial_state(), {"position": np.zeros((4, 3))}, np)
    np.testing.assert_allclose(out["velocity"], np.broadcast_to([0.5, 1.0, 1.5], (4, 3)))
    with pytest.raises(av.ParameterError):
        HolonomicPointToPoint([[1.0, 2.0]])


def test_offaxis_mapping_runs_consensus_on_unicycles():
    n, dd = 5, 0.2
    rng = np.random.default_rng(5)
    pose0 = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-3, 3, n)])
    d = av.Diagram()
    veh = d.add(av.vehicles.Unicycle(pose0=pose0), name="veh")
    pt = d.add(OffAxisPoint(n, dd), name="pt")
    c = d.add(Consensus(n, adjacency=np.ones((n, n))), name="c")
    h = d.add(HolonomicToUnicycle(n, dd), name="h")
    d.connect(veh.pose, pt.pose)
    d.connect(pt.position, c.position)
    d.connect(veh.pose, h.pose)
    d.connect(c.velocity, h.velocity)
    d.connect(h.cmd, veh.cmd)
    res = av.simulate(d, 10.0, dt=0.01, log=[pt.position])
    pts = res[pt.position]
    p0 = pose0[:, :2] + dd * np.column_stack([np.cos(pose0[:, 2]), np.sin(pose0[:, 2])])
    # the points obey the single-integrator consensus exactly
    from scipy.linalg import expm
    lap = n * np.eye(n) - np.ones((n, n))
    np.testing.assert_allclose(pts[-1], expm(-lap * 10.0) @ p0, atol=1e-3)
    np.testing.assert_allclose(pts[20], expm(-lap * 0.2) @ p0, atol=1e-3)


def test_flocking_law_equals_the_equations_pair_by_pair():
    # reference: eq. (23) of Olfati-Saber (2006) written out per pair
    from avblocks.controllers import flocking_law
    rng = np.random.default_rng(11)
    n, d, r, eps, a, b, h, c1, c2 = 30, 2.0, 2.4, 0.1, 4.0, 6.0, 0.2, 1.3, 0.7
    q, p = rng.uniform(0, 8, (n, 2)), rng.uniform(-1, 1, (n, 2))
    full = np.linalg.norm(q[:, None] - q[None], axis=-1)
    idx = np.full((n, 10), -1)
    for i in range(n):
        js = [j for j in np.argsort(full[i], kind="stable") if j != i and full[i, j] <= r][:10]
        idx[i, :len(js)] = js

    def snorm(z):
        return (np.sqrt(1 + eps * z @ z) - 1) / eps

    def rho(x):
        if x < h:
            return 1.0
        return 0.5 * (1 + np.cos(np.pi * (x - h) / (1 - h))) if x <= 1 else 0.0

    r_a, d_a = snorm(np.array([r])), snorm(np.array([d]))
    cc = abs(a - b) / np.sqrt(4 * a * b)
    want = np.zeros((n, 2))
    for i in range(n):
        for j in idx[i][idx[i] >= 0]:
            z = q[j] - q[i]
            s = snorm(z)
            y = s - d_a + cc
            phi = 0.5 * ((a + b) * y / np.sqrt(1 + y * y) + (a - b))
            want[i] += c1 * rho(s / r_a) * phi * z / np.sqrt(1 + eps * z @ z)
            want[i] += c2 * rho(s / r_a) * (p[j] - p[i])
    got = flocking_law(q, p, idx, d, r, eps=eps, a=a, b=b, h=h, c1=c1, c2=c2)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
