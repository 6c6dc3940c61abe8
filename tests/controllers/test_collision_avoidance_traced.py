"""The traceable joint CBF QP (consensus ADMM in ``xp``) and both modes of
CollisionAvoidance under the compiled backend.

Truth: scipy's SLSQP on the QP written out pair by pair in the test, and
Clarabel (interior point) where installed (CI has it); gradients against
central finite differences of the NumPy solver; compiled runs against the
NumPy engine.
"""

import os

import numpy as np
import pytest
from scipy.optimize import minimize

import avblocks as av
from avblocks.controllers import CollisionAvoidance, HolonomicPointToPoint
from avblocks.controllers.collision_avoidance import (
    joint_filter,
    joint_safety_filter,
    neighbor_edges,
    pairs_from_neighbors,
)
from avblocks.environment.neighbors import radius_neighbors

# stated accuracy of the ADMM solver (defaults: at most 500 iterations,
# tol 1e-10) against an exact active-set solution (quadprog), velocities of
# order 1: 3e-10 measured on these clusters. Clarabel itself is only
# accurate to about 3e-7 on them (against quadprog), so it is compared
# with that looser tolerance.
SOLUTION_TOL = 1e-9
CLARABEL_TOL = 1e-6
CONSTRAINT_TOL = 1e-9     # relative to 1 + max |u_nominal|


def _dense(p, radius, gamma, sensing):
    """Rows ``-(p_i - p_j)^T (u_i - u_j) <= gamma/2 h_ij`` one pair at a time."""
    n, dim = p.shape
    rows, rhs = [], []
    for i in range(n):
        for j in range(i + 1, n):
            e = p[i] - p[j]
            if np.linalg.norm(e) > sensing:
                continue
            row = np.zeros(n * dim)
            row[i * dim:(i + 1) * dim] = -e
            row[j * dim:(j + 1) * dim] = e
            rows.append(row)
            rhs.append(0.5 * gamma * (e @ e - radius ** 2))
    return np.array(rows).reshape(-1, n * dim), np.array(rhs)


def _slsqp(w, a, b):
    w = w.ravel()
    r = minimize(lambda u: np.sum((u - w) ** 2), w, jac=lambda u: 2 * (u - w),
                 constraints=[{"type": "ineq", "fun": lambda u: b - a @ u,
                               "jac": lambda u: -a}],
                 method="SLSQP", options={"ftol": 1e-15, "maxiter": 1000})
    return r.x


def _safe_cloud(rng, n, dim, radius, box):
    p = np.zeros((0, dim))
    while len(p) < n:
        q = rng.uniform(-box, box, dim)
        if len(p) == 0 or np.min(np.linalg.norm(p - q, axis=1)) > 1.02 * radius:
            p = np.vstack([p, q])
    return p


def _jammed(rng, n=20, radius=0.85, box=2.6):
    """A dense cluster whose nominal velocities all point into it."""
    p = _safe_cloud(rng, n, 2, radius, box)
    w = -p / np.linalg.norm(p, axis=1, keepdims=True) + 0.1 * rng.normal(size=(n, 2))
    return p, w


@pytest.mark.parametrize("dim", [2, 3])
def test_admm_equals_slsqp_on_small_problems(dim):
    rng = np.random.default_rng(11 + dim)
    active = 0
    for _trial in range(25):
        n = int(rng.integers(2, 7))
        radius, gamma, sensing = 0.5, float(rng.uniform(0.5, 3.0)), 1.5
        p = _safe_cloud(rng, n, dim, radius, 1.0)
        w = rng.normal(size=(n, dim)) * 2.0
        a, b = _dense(p, radius, gamma, sensing)
        idx, _ = radius_neighbors(p, sensing, n)
        got, res = joint_filter(p, w, idx, radius, gamma)
        assert res <= 1e-10 * (1 + np.abs(w).max())           # it converged
        if len(b) == 0:
            np.testing.assert_allclose(got, w)
            continue
        want = _slsqp(w, a, b).reshape(n, dim)
        np.testing.assert_allclose(got, want, atol=1e-6)      # SLSQP's own accuracy
        assert np.max(a @ got.ravel() - b) <= CONSTRAINT_TOL * (1 + np.abs(w).max())
        active += int(np.any(a @ want.ravel() - b > -1e-9))
    assert active >= 8                                         # constraints did work


def test_admm_equals_quadprog_and_clarabel_on_jammed_clusters():
    if os.environ.get("CI"):
        import clarabel  # noqa: F401
        import quadprog
    else:
        pytest.importorskip("clarabel")
        quadprog = pytest.importorskip("quadprog")
    rng = np.random.default_rng(5)
    for trial in range(6):
        p, w = _jammed(rng)
        idx, _ = radius_neighbors(p, 3.0, 19)
        rh = 1.0 if trial % 2 else 0.0
        clar = joint_safety_filter(p, w, pairs_from_neighbors(idx), 0.85, 2.0, rh)
        got, _ = joint_filter(p, w, idx, 0.85, 2.0, rh)
        a, b = _dense(p, 0.85, 2.0, 3.0)
        w_biased = w.copy()
        if rh:       # the right-hand bias, written out: agents with a partner < 2 D_s
            dd = np.linalg.norm(p[:, None] - p[None], axis=-1) + 9 * np.eye(len(p))
            near = (dd < 2 * 0.85).any(axis=1)
            w_biased[near] += rh * np.stack([w[near, 1], -w[near, 0]], axis=-1)
        want = quadprog.solve_qp(np.eye(w.size), w_biased.ravel(), -a.T, -b, 0)[0]
        np.testing.assert_allclose(got.ravel(), want, atol=SOLUTION_TOL, rtol=0)
        np.testing.assert_allclose(got, clar, atol=CLARABEL_TOL, rtol=0)
        assert np.max(a @ got.ravel() - b) <= CONSTRAINT_TOL * (1 + np.abs(w).max())
        # the jam is real: many constraints active at the optimum
        assert np.sum(a @ want - b > -1e-7) >= 5


def test_edges_are_the_union_of_the_lists_each_pair_once():
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 4, (40, 2))
    idx, _ = radius_neighbors(p, 1.0, 3)               # k-capped: not symmetric
    ei, ej, ok = neighbor_edges(idx)
    got = sorted((min(i, j), max(i, j)) for i, j, o in zip(ei, ej, ok) if o)
    assert got == sorted(map(tuple, pairs_from_neighbors(idx)))   # no pair twice
    pad = idx.ravel() < 0
    assert pad.any() and np.all(ei[pad] == ej[pad])      # padding points at itself


def test_no_active_constraint_returns_the_nominal_velocity_exactly():
    p = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    w = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])    # moving apart
    idx = np.array([[1, 2], [0, 2], [0, 1]])
    u, res = joint_filter(p, w, idx, 0.5, 1.0)
    np.testing.assert_array_equal(u, w)
    assert res == 0.0


def test_two_agents_head_on_analytic():
    """Two agents on the x axis driving at each other: the joint optimum
    shares the correction equally, ``u_x = -+ (gamma/4) h / |d|`` projected."""
    d, r, g = 2.0, 1.0, 1.0
    p = np.array([[0.0, 0.0], [d, 0.0]])
    w = np.array([[1.0, 0.3], [-1.0, 0.0]])
    u, _ = joint_filter(p, w, np.array([[1], [0]]), r, g)
    # constraint d (u_1x - u_0x) ... : -(p0-p1).(u0-u1) = d (u0x - u1x) <= g/2 h
    h = d * d - r * r
    s = 0.5 * g * h / d                                       # allowed closing speed
    np.testing.assert_allclose(u[:, 1], w[:, 1], atol=1e-12)   # tangential kept
    np.testing.assert_allclose(u[0, 0] - u[1, 0], s, atol=1e-10)
    np.testing.assert_allclose(u[0, 0] + u[1, 0], 0.0, atol=1e-10)   # shared equally


@pytest.mark.jax
def test_jit_vmap_and_grad_of_the_joint_filter():
    jax = pytest.importorskip("jax")
    jax.config.update("jax_enable_x64", True)
    jnp = jax.numpy
    rng = np.random.default_rng(3)
    p, w = _jammed(rng, n=8, radius=0.8, box=1.7)
    idx, _ = radius_neighbors(p, 2.5, 7)
    ref, _ = joint_filter(p, w, idx, 0.8, 2.0, 0.5)
    f = jax.jit(lambda p, w: joint_filter(p, w, jnp.asarray(idx), 0.8, 2.0, 0.5, jnp)[0])
    np.testing.assert_allclose(np.asarray(f(jnp.asarray(p), jnp.asarray(w))), ref,
                               atol=1e-12)
    # vmap over a batch of nominal velocities
    ws = np.stack([w, -w, 2 * w])
    got = jax.vmap(f, in_axes=(None, 0))(jnp.asarray(p), jnp.asarray(ws))
    for k in range(3):
        np.testing.assert_allclose(np.asarray(got[k]),
                                   joint_filter(p, ws[k], idx, 0.8, 2.0, 0.5)[0],
                                   atol=1e-12)
    # gradient of a cost of the filtered velocities w.r.t. positions and
    # nominal velocities, against central differences of the NumPy solver
    c = rng.normal(size=w.shape)

    def cost_np(p, w):
        return float(np.sum(c * joint_filter(p, w, idx, 0.8, 2.0, 0.5)[0]))

    gp, gw = jax.jit(jax.grad(lambda p, w: jnp.sum(jnp.asarray(c) * f(p, w)),
                              argnums=(0, 1)))(jnp.asarray(p), jnp.asarray(w))
    eps = 1e-6
    for g, x, which in ((gw, w, 1), (gp, p, 0)):
        fd = np.zeros_like(x)
        for i in range(x.shape[0]):
            for k in range(x.shape[1]):
                e = np.zeros_like(x)
                e[i, k] = eps
                args_p = [p + e, p - e] if which == 0 else [p, p]
                args_w = [w + e, w - e] if which == 1 else [w, w]
                fd[i, k] = (cost_np(args_p[0], args_w[0])
                            - cost_np(args_p[1], args_w[1])) / (2 * eps)
        np.testing.assert_allclose(np.asarray(g), fd, atol=1e-5)
        assert np.abs(fd).max() > 1e-2                       # not a trivial zero


def _swap_diagram(mode, n=10, ratio=4.0, circle=2.0, capacity=None, k_max=4):
    ds = circle / ratio
    ang = 2 * np.pi * np.arange(n) / n
    p0 = circle * np.column_stack([np.cos(ang), np.sin(ang)])
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(p0), name="ag")
    nom = d.add(HolonomicPointToPoint(-p0[:, None, :], gain=1.0, v_max=1.0, radius=0.05),
                name="nom")
    ca = d.add(CollisionAvoidance(n, ds, gamma=2.0, right_hand=1.0, sensing_range=3 * ds,
                                  mode=mode, capacity=capacity, k_max=k_max), name="ca")
    d.connect(ag.y, nom.position)
    d.connect(ag.y, ca.position)
    d.connect(nom.velocity, ca.velocity_nominal)
    d.connect(ca.velocity, ag.u)
    return d


@pytest.mark.jax
@pytest.mark.parametrize("mode, k_max", [("joint", 4), ("joint", None), ("agent", 4)])
def test_both_modes_with_sensing_range_compile_and_equal_numpy(mode, k_max):
    pytest.importorskip("jax")
    ref = av.simulate(_swap_diagram(mode, k_max=k_max), 6.0, dt=0.05, solver="euler",
                      log=["ag.y"], progress=False)
    got = av.simulate(_swap_diagram(mode, capacity=10, k_max=k_max), 6.0, dt=0.05,
                      solver="euler", log=["ag.y"], backend="jax")
    assert np.max(np.abs(np.asarray(got["ag.y"]) - np.asarray(ref["ag.y"]))) < 1e-9
    # and the filter did work: the agents met in the middle
    x = np.asarray(ref["ag.y"])
    assert np.linalg.norm(x, axis=2).min() < 1.0


@pytest.mark.jax
def test_compiled_sensing_range_without_capacity_is_planned_by_the_engine():
    """No capacity=: the compiled engine plans the block's own search from
    the initial positions and the run equals the NumPy one."""
    pytest.importorskip("jax")
    kw = dict(t_final=1.0, dt=0.05, solver="euler", log=["ag.y"])
    ref = av.simulate(_swap_diagram("joint"), **kw)
    got = av.simulate(_swap_diagram("joint"), backend="jax", **kw)
    np.testing.assert_allclose(got["ag.y"], ref["ag.y"], atol=1e-9)


@pytest.mark.jax
def test_gradient_through_a_compiled_run_equals_finite_differences():
    """d cost / d (gamma, radius) by reverse mode through a compiled run of
    the joint filter, against central differences of NumPy runs (the
    neighbour sets do not change under the small perturbations)."""
    jax = pytest.importorskip("jax")
    jnp = jax.numpy
    # ratio 2.5: sensing 1.2 m, hexagon sides 1 m (at ratio 3 they would sit
    # exactly at the sensing range, and round-off would pick the pairs)
    n, t_final = 6, 2.0
    c = np.random.default_rng(4).normal(size=(n, 2))

    def cost_np(res):
        return float(np.sum(c * np.asarray(res["ag.y"])[-1]))

    def run_np(**params):
        return cost_np(av.simulate(_swap_diagram("joint", n=n, ratio=2.5, circle=1.0,
                                                 k_max=None),
                                   t_final, dt=0.05, solver="euler", log=["ag.y"],
                                   params=params, progress=False))

    g = av.grad(lambda r: jnp.sum(jnp.asarray(c) * r["ag.y"][-1]),
                _swap_diagram("joint", n=n, ratio=2.5, circle=1.0, capacity=n, k_max=None),
                ["ca.gamma", "ca.radius"], t_final, dt=0.05, solver="euler", log=["ag.y"])
    base = {"ca.gamma": 2.0, "ca.radius": 0.4}
    for name, eps in (("ca.gamma", 1e-5), ("ca.radius", 1e-6)):
        hi = dict(base, **{name: base[name] + eps})
        lo = dict(base, **{name: base[name] - eps})
        fd = (run_np(**hi) - run_np(**lo)) / (2 * eps)
        assert abs(fd) > 1e-3, name                          # the filter acted
        assert float(g[name]) == pytest.approx(fd, rel=1e-4, abs=1e-7), name


def test_overlapping_and_coincident_agents_give_finite_separating_velocities():
    """Agents already inside the safety radius (h < 0): the joint QP is
    still feasible (a uniform expansion satisfies every pair) and the solver
    meets each constraint; two coincident agents (no direction to push)
    leave their own constraint unmet and nothing else broken."""
    p = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.0], [0.15, 0.2]])
    w = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    idx = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    radius, gamma = 0.5, 1.0
    u, res = joint_filter(p, w, idx, radius, gamma)
    assert np.all(np.isfinite(u)) and res < 1e-9
    for i in range(4):
        for j in range(i + 1, 4):
            e = p[i] - p[j]
            if e @ e == 0:
                continue
            # -(p_i - p_j).(u_i - u_j) <= gamma/2 h_ij < 0: they separate
            assert -e @ (u[i] - u[j]) <= 0.5 * gamma * (e @ e - radius ** 2) + 1e-9
