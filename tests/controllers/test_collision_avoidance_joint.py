"""Joint CBF safety filter (one sparse QP over all agents, Clarabel).

Truth: the QP written out pair by pair in the test and solved by quadprog
(dense active set, Goldfarb-Idnani) and cvxopt (interior point); the
antipodal swap checked for arrival and the closest approach of every pair.
"""

import os

import numpy as np
import pytest
from scipy.spatial.distance import pdist

import avblocks as av
from avblocks.controllers import CollisionAvoidance, HolonomicPointToPoint
from avblocks.controllers.collision_avoidance import (
    joint_min_norm_qp,
    joint_safety_filter,
    pair_constraints,
    pairs_from_neighbors,
    pairs_in_range,
)
from avblocks.core.errors import ParameterError
from avblocks.environment.neighbors import radius_neighbors

try:
    import clarabel  # noqa: F401
except ImportError:  # pragma: no cover - the safety extra is missing
    if os.environ.get("CI"):
        raise
    pytest.skip("clarabel (avblocks[safety]) not installed", allow_module_level=True)

if os.environ.get("CI"):
    import quadprog
else:
    quadprog = pytest.importorskip("quadprog")


def _dense_problem(p, u_nom, radius, gamma, sensing):
    """The joint QP built straight from the equations, one pair at a time."""
    n, dim = p.shape
    rows, rhs = [], []
    for i in range(n):
        for j in range(i + 1, n):
            e = p[i] - p[j]
            if np.linalg.norm(e) > sensing:
                continue
            row = np.zeros(n * dim)
            row[i * dim:(i + 1) * dim] = -e          # -(p_i - p_j)^T u_i
            row[j * dim:(j + 1) * dim] = e           # +(p_i - p_j)^T u_j
            rows.append(row)
            rhs.append(0.5 * gamma * (e @ e - radius ** 2))
    return np.array(rows).reshape(-1, n * dim), np.array(rhs)


def _quadprog(u_nom, a, b):
    g = np.eye(u_nom.size)
    return quadprog.solve_qp(g, u_nom.ravel(), -a.T, -b, 0)[0].reshape(u_nom.shape)


def _random_safe_positions(rng, n, dim, radius, box):
    p = np.zeros((0, dim))
    while len(p) < n:
        q = rng.uniform(-box, box, dim)
        if len(p) == 0 or np.min(np.linalg.norm(p - q, axis=1)) > 1.05 * radius:
            p = np.vstack([p, q])
    return p


@pytest.mark.parametrize("dim", [2, 3])
def test_joint_qp_equals_quadprog_and_is_feasible(dim):
    rng = np.random.default_rng(7 + dim)
    active = 0
    for _trial in range(40):
        n = int(rng.integers(2, 8))
        radius, gamma, sensing = 0.5, float(rng.uniform(0.5, 3.0)), 1.5
        p = _random_safe_positions(rng, n, dim, radius, 1.0)
        u_nom = rng.normal(size=(n, dim)) * 2.0
        a_ref, b_ref = _dense_problem(p, u_nom, radius, gamma, sensing)
        pairs = pairs_in_range(p, sensing)
        a, b = pair_constraints(p, pairs, radius, gamma)
        assert a.shape == (len(b_ref), n * dim)
        got = joint_safety_filter(p, u_nom, pairs, radius, gamma)
        if len(b_ref) == 0:
            np.testing.assert_allclose(got, u_nom)
            continue
        want = _quadprog(u_nom, a_ref, b_ref)
        np.testing.assert_allclose(got, want, atol=1e-6)
        assert np.max(a_ref @ got.ravel() - b_ref) <= 1e-7
        active += int(np.any(a_ref @ want.ravel() - b_ref > -1e-9))
    assert active >= 10                      # the constraints did real work


def test_joint_min_norm_qp_equals_cvxopt_on_random_sparse_problems():
    if os.environ.get("CI"):
        import cvxopt
    else:
        cvxopt = pytest.importorskip("cvxopt")
    import scipy.sparse as sp
    cvxopt.solvers.options.update(show_progress=False, abstol=1e-12, reltol=1e-12,
                                  feastol=1e-12)
    rng = np.random.default_rng(3)
    for _trial in range(20):
        nv, m = int(rng.integers(2, 12)), int(rng.integers(1, 15))
        a = sp.random(m, nv, density=0.4, random_state=rng, format="csc")
        a = a + sp.csc_matrix((rng.normal(size=m), (np.arange(m), rng.integers(0, nv, m))),
                              shape=(m, nv))
        b = rng.uniform(0.0, 1.0, m)             # u = 0 feasible
        u0 = rng.normal(size=(nv, 1)) * 3.0
        got, status = joint_min_norm_qp(u0, a, b)
        assert status == "Solved"
        ad = a.toarray()
        r = cvxopt.solvers.qp(cvxopt.matrix(np.eye(nv)), cvxopt.matrix(-u0.ravel()),
                              cvxopt.matrix(ad), cvxopt.matrix(b))
        want = np.array(r["x"]).ravel()
        np.testing.assert_allclose(got.ravel(), want, atol=1e-6)
        assert np.max(ad @ got.ravel() - b) <= 1e-8


def test_pairs_match_brute_force_and_neighbour_lists():
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 5, (60, 2))
    got = {tuple(x) for x in pairs_in_range(p, 1.0)}
    d = np.linalg.norm(p[:, None] - p[None], axis=-1)
    want = {(i, j) for i in range(60) for j in range(i + 1, 60) if d[i, j] <= 1.0}
    assert got == want
    idx, _ = radius_neighbors(p, 1.0, 60)
    assert {tuple(x) for x in pairs_from_neighbors(idx)} == want
    assert len(pairs_in_range(p, np.inf)) == 60 * 59 // 2


def test_block_joint_mode_and_bad_mode():
    rng = np.random.default_rng(2)
    p = _random_safe_positions(rng, 12, 2, 0.4, 1.5)
    u_nom = rng.normal(size=(12, 2))
    blk = CollisionAvoidance(12, 0.4, gamma=1.5, right_hand=0.5, sensing_range=1.2,
                             mode="joint", solver="clarabel", k_max=None)
    assert blk.traceable is False
    out = blk.output(0.0, {}, {"position": p, "velocity_nominal": u_nom}, np)["velocity"]
    want = joint_safety_filter(p, u_nom, pairs_in_range(p, 1.2), 0.4, 1.5, 0.5)
    np.testing.assert_allclose(out, want)
    # the port: the union of the neighbour lists
    port = CollisionAvoidance(12, 0.4, gamma=1.5, right_hand=0.5, mode="joint",
                              solver="clarabel")
    idx, _ = radius_neighbors(p, 1.2, 11)
    np.testing.assert_allclose(
        port.output(0.0, {}, {"position": p, "velocity_nominal": u_nom,
                              "neighbors": idx}, np)["velocity"], want, atol=1e-9)
    # the default (joint, built-in ADMM) and the per-agent mode both trace
    assert CollisionAvoidance(3, 0.4).traceable is True
    assert CollisionAvoidance(3, 0.4).mode == "joint"
    assert CollisionAvoidance(3, 0.4, mode="agent").traceable is True
    with pytest.raises(ParameterError, match="mode"):
        CollisionAvoidance(3, 0.4, mode="central")
    with pytest.raises(ParameterError, match="solver"):
        CollisionAvoidance(3, 0.4, solver="osqp")


def _swap(ratio, mode, n=20, circle=3.0, dt=0.05, t_final=30.0, right_hand=1.0,
          solver="admm"):
    """Perfectly symmetric antipodal swap (no jitter, equal speed caps)."""
    ds = circle / ratio
    ang = 2 * np.pi * np.arange(n) / n
    p0 = circle * np.column_stack([np.cos(ang), np.sin(ang)])
    goals = -p0
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(p0), name="ag")
    nom = d.add(HolonomicPointToPoint(goals[:, None, :], gain=1.0, v_max=1.0,
                                      radius=0.05), name="nom")
    ca = d.add(CollisionAvoidance(n, ds, gamma=2.0, right_hand=right_hand,
                                  sensing_range=4 * ds, mode=mode, solver=solver),
                name="ca")
    d.connect(ag.y, nom.position)
    d.connect(ag.y, ca.position)
    d.connect(nom.velocity, ca.velocity_nominal)
    d.connect(ca.velocity, ag.u)
    res = av.simulate(d, t_final, dt=dt, log=[ag.y], solver="euler")
    x = res[ag.y]
    closest = min(pdist(xk).min() for xk in x)
    err = np.linalg.norm(x - goals, axis=2).max(axis=1)
    arrived = np.nonzero(err < 0.1)[0]
    return ds, closest, (res.t[arrived[0]] if len(arrived) else None), err[-1]


@pytest.mark.parametrize("ratio", [4.0, 5.88, 8.0, 10.0])
def test_joint_swap_20_agents_completes_safely(ratio):
    ds, closest, t_arrive, final = _swap(ratio, "joint")
    assert closest >= ds - 1e-6, (closest, ds)
    assert t_arrive is not None and final < 0.1, final
    assert t_arrive < 12.0                    # 7.3-8.3 s measured; straight lines: 6 s


@pytest.mark.parametrize("ratio", [4.0, 5.88, 8.0])
def test_joint_swap_with_clarabel_completes_too(ratio):
    ds, closest, t_arrive, final = _swap(ratio, "joint", solver="clarabel")
    assert closest >= ds - 1e-6, (closest, ds)
    assert t_arrive is not None and final < 0.1, final


def test_split_filter_jams_where_joint_completes():
    """The motivation: the per-agent filter stops for good in the same swap."""
    ds, closest, t_arrive, final = _swap(5.88, "agent", t_final=20.0)
    assert closest >= ds - 1e-6
    assert t_arrive is None and final > 1.0
