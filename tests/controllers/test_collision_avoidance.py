"""CBF safety filter: exact QP (vs scipy SLSQP + KKT) and a 20-agent antipodal swap."""

import numpy as np
from scipy.optimize import minimize

import avblocks as av
from avblocks.controllers import CollisionAvoidance, HolonomicPointToPoint
from avblocks.controllers.collision_avoidance import min_norm_qp, safety_filter
from avblocks.environment.neighbors import radius_neighbors


def _slsqp(u0, a, b):
    cons = [{"type": "ineq", "fun": lambda u, ak=ak, bk=bk: bk - ak @ u,
             "jac": lambda u, ak=ak: -ak} for ak, bk in zip(a, b)]
    r = minimize(lambda u: np.sum((u - u0) ** 2), u0, jac=lambda u: 2 * (u - u0),
                 constraints=cons, method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
    return r.x


def test_exact_qp_matches_solver_2d_and_3d():
    rng = np.random.default_rng(0)
    for dim in (2, 3):
        n, k = 200, 5
        a = rng.normal(size=(n, k, dim))
        b = rng.normal(size=(n, k)) + 0.5          # u = 0 often infeasible: real work
        mask = rng.uniform(size=(n, k)) < 0.8
        u0 = rng.normal(size=(n, dim)) * 2
        # keep only feasible instances (checked by a point that satisfies all)
        got = min_norm_qp(u0, a, b, mask)
        for i in range(n):
            ai, bi = a[i][mask[i]], b[i][mask[i]]
            want = _slsqp(u0[i], ai, bi) if len(ai) else u0[i]
            if len(ai) and np.any(ai @ want - bi > 1e-7):
                continue                            # infeasible instance
            np.testing.assert_allclose(got[i], want, atol=1e-5)
            assert np.all(ai @ got[i] - bi <= 1e-9)


def test_filter_is_identity_when_safe_and_kkt_when_active():
    p = np.array([[0.0, 0.0], [1.0, 0.0]])
    idx = np.array([[1], [0]])
    away = np.array([[-1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(safety_filter(p, away, idx, 0.5), away)
    toward = np.array([[2.0, 0.3], [-2.0, 0.0]])
    u = safety_filter(p, toward, idx, 0.5, gamma=1.0)
    # half-responsibility constraint active: (p_i - p_j).u_i = -(gamma/4) h
    h = 1.0 - 0.25
    np.testing.assert_allclose(u[0, 0], 0.25 * h, atol=1e-12)
    np.testing.assert_allclose(u[0, 1], 0.3, atol=1e-12)      # tangential part kept
    np.testing.assert_allclose(u[1, 0], -0.25 * h, atol=1e-12)


def test_antipodal_swap_20_agents_safe_and_all_arrive():
    n, radius, ds = 20, 4.0, 0.6
    ang = 2 * np.pi * np.arange(n) / n
    rng = np.random.default_rng(1)
    p0 = radius * np.column_stack([np.cos(ang), np.sin(ang)]) + rng.normal(0, 0.02, (n, 2))
    goals = -radius * np.column_stack([np.cos(ang), np.sin(ang)])
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(p0), name="ag")
    nom = d.add(HolonomicPointToPoint(goals[:, None, :], gain=1.0, v_max=1.0,
                                      radius=0.05), name="nom")
    ca = d.add(CollisionAvoidance(n, ds, gamma=2.0, right_hand=0.5,
                                  sensing_range=2.0, k_max=4, mode="agent"), name="ca")
    d.connect(ag.y, nom.position)
    d.connect(ag.y, ca.position)
    d.connect(nom.velocity, ca.velocity_nominal)
    d.connect(ca.velocity, ag.u)
    res = av.simulate(d, 50.0, dt=0.05, log=[ag.y])
    x = res[ag.y]
    iu = np.triu_indices(n, 1)
    dmin = np.linalg.norm(x[:, :, None, :] - x[:, None, :, :], axis=-1)[:, iu[0], iu[1]].min()
    assert dmin >= ds * (1 - 1e-6), dmin
    assert np.linalg.norm(x[-1] - goals, axis=1).max() < 0.1
    # neighbours given through the port give the same velocities
    idx, _ = radius_neighbors(x[100], 2.0, 4)
    blk = CollisionAvoidance(n, ds, gamma=2.0, mode="agent")
    u_nom = np.ones((n, 2))
    np.testing.assert_allclose(
        blk.output(0, {}, {"position": x[100], "velocity_nominal": u_nom,
                           "neighbors": idx}, np)["velocity"],
        safety_filter(x[100], u_nom, idx, ds, 2.0))
